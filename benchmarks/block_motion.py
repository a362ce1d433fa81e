"""How often exploring episodes touch and move the object, over the course of a run.

Reads the replay buffer saved in each run's latest checkpoint (every exploring episode of
the run while the buffer has not wrapped) and prints, per block of episodes, the share in
which the gripper came within 5 cm of the object, and in which the object moved more than
1 cm and 5 cm from where it started. For the Fetch object tasks (FetchPush, FetchSlide,
FetchPickAndPlace), where the achieved goal is the object's position and the observation
begins with the gripper's.

It tells a run that does not learn for want of data (the object seldom moves) from one that
does not learn from the data it has.

    python benchmarks/block_motion.py runs/push-sweep/FetchPush-v4-her-s2 runs/push-sweep/FetchPush-v4-dtd-s2
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from dtd.agents.buffer import slots_oldest_first
from dtd.errors import CheckpointError
from dtd.training.checkpoint import Checkpoint
from dtd.training.run_dir import RunDir

OBJECT_TASKS = ("FetchPush", "FetchSlide", "FetchPickAndPlace")
NEAR = 0.05
"""The gripper is near the object within this distance (m)."""
MOVED = (0.01, 0.05)
"""Displacements (m) of the object from its start that count as moving it."""


def episode_motion(run: Path) -> tuple[int, np.ndarray, np.ndarray]:
    """Index of the first stored episode, per-episode largest displacement of the object and
    closest approach of the gripper, in the order the episodes were collected."""
    checkpoint = Checkpoint.read(RunDir(run).latest)
    env_id = checkpoint.env_id
    if not env_id.startswith(OBJECT_TASKS):
        raise SystemExit(f"{run}: {env_id} is not one of the Fetch object tasks ({', '.join(OBJECT_TASKS)})")
    buffer = checkpoint.agent["buffer"]
    size, added = int(buffer["size"]), int(buffer["episodes_added"])
    achieved = buffer["data"]["achieved_goal"].numpy()[:size]
    gripper = buffer["data"]["obs"].numpy()[:size, :, 0:3]
    order = slots_oldest_first(size, added, int(buffer["next_index"]))
    achieved, gripper = achieved[order], gripper[order]
    displacement = np.linalg.norm(achieved - achieved[:, :1], axis=-1).max(axis=1)
    approach = np.linalg.norm(gripper - achieved, axis=-1).min(axis=1)
    return added - size, displacement, approach


def by_block(flags: np.ndarray, block: int) -> str:
    """The share of true flags in each run of ``block`` episodes."""
    return " ".join(f"{np.mean(flags[i : i + block]):.2f}" for i in range(0, len(flags), block))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="+", type=Path, help="run directories (with checkpoints/latest.pt)")
    parser.add_argument("--block", type=int, default=500, help="episodes per printed block")
    args = parser.parse_args()
    if args.block < 1:
        parser.error("--block must be at least 1")
    for run in args.runs:
        try:
            first, displacement, approach = episode_motion(run)
        except CheckpointError as exc:
            raise SystemExit(f"error: {exc}") from None
        print(f"{run} (episodes {first + 1}-{first + len(displacement)}, blocks of {args.block})")
        print(f"  gripper within {NEAR * 100:.0f} cm  {by_block(approach < NEAR, args.block)}")
        for moved in MOVED:
            print(f"  object moved > {moved * 100:.0f} cm  {by_block(displacement > moved, args.block)}")


if __name__ == "__main__":
    main()
