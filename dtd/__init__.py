"""dtd: train and explain hierarchical goal-conditioned agents (Dot-to-Dot, HER, DDPG)."""

import os
import sys

__version__ = "0.1.0"

# Frames are drawn offscreen: without a display, MuJoCo is told to use EGL (set before MuJoCo
# is first imported; a MUJOCO_GL chosen by the user is kept).
if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
    os.environ.setdefault("MUJOCO_GL", "egl")
