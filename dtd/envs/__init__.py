"""Environments: making goal-conditioned tasks by id, describing them with an ``EnvSpec``, and
fast reads of the robot's joints."""
