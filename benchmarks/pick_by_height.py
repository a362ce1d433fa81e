"""Success of a trained FetchPickAndPlace run split by where its goal lies: on the table (at the
height of the block's start) or in the air, by height above the start; and how often the block
was lifted at all. Deterministic episodes of the run's latest checkpoint, the evaluation seed
that ``dtd eval`` uses.

    python benchmarks/pick_by_height.py runs/record/pick/FetchPickAndPlace-v4-dtd-s100 --episodes 100
"""

from __future__ import annotations

import argparse

from dtd.training.rollout import run_many
from dtd.training.trained_run import load_run

LIFTED_M = 0.02
"""The block counts as lifted once it rose this far above its start."""
HEIGHT_BANDS_M = ((0.01, 0.15), (0.15, 0.30), (0.30, 0.50))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("run_dir")
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args()
    with load_run(args.run_dir, envs=10) as loaded:
        episodes = run_many(loaded.envs, loaded.agent, loaded.spec, args.episodes, False, loaded.rng)
    start_height = episodes.achieved_goal[:, 0, 2]
    height = episodes.desired_goal[:, 2] - start_height
    rose = (episodes.achieved_goal[:, :, 2] - start_height[:, None]).max(axis=1)
    lifted = rose > LIFTED_M
    in_air = height > HEIGHT_BANDS_M[0][0]
    success = episodes.success
    print(f"{args.run_dir}: {args.episodes} episodes, success {success.mean():.2f}")
    print("| goal | episodes | success | block lifted |")
    print("|---|---|---|---|")
    for name, rows in (("on the table", ~in_air), ("in the air", in_air)):
        print(f"| {name} | {rows.sum()} | {success[rows].mean():.2f} | {lifted[rows].mean():.2f} |")
    for low, high in HEIGHT_BANDS_M:
        rows = (height > low) & (height <= high)
        if rows.any():
            band = f"{low * 100:.0f}-{high * 100:.0f} cm up"
            print(f"| {band} | {rows.sum()} | {success[rows].mean():.2f} | {lifted[rows].mean():.2f} |")


if __name__ == "__main__":
    main()
