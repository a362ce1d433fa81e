"""dtd: train and explain hierarchical goal-conditioned agents (Dot-to-Dot, HER, DDPG)."""

__version__ = "0.1.0"
