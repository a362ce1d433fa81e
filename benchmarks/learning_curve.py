"""Train one agent for a budget of env steps and print its learning curve.

Eval success against env steps and wall time, at marks along the way; resumes a run
left unfinished in the same directory. A benchmark, not a test: it prints figures.

    python benchmarks/learning_curve.py --env FetchPush-v4 --algo her --steps 300000 \
        --run-dir runs/bench-push-her-0
"""

from __future__ import annotations

import argparse
import csv
import platform
from pathlib import Path

from dtd.config import Algo, TrainConfig, with_settings
from dtd.training.lifecycle import train_for_steps
from dtd.training.run_dir import RunDir, read_config


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--env", default="FetchPush-v4")
    parser.add_argument("--algo", default="her", choices=[a.value for a in Algo])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=300_000, help="env steps to train for")
    parser.add_argument("--marks", default="50000,100000,200000,300000", help="env steps to report at")
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: automatic)")
    parser.add_argument("--run-dir", type=Path, required=True)
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="any other setting, e.g. low_relabel_window=episode or high.batch_size=128 (JSON values)",
    )
    args = parser.parse_args()

    base = with_settings(
        TrainConfig(env=args.env, algo=Algo(args.algo), seed=args.seed, threads=args.threads), args.set
    )
    train_for_steps(base, args.steps, args.run_dir)
    run = RunDir(args.run_dir)
    report(run, [int(m) for m in args.marks.split(",")], read_config(run))


def report(run: RunDir, marks: list[int], config: TrainConfig, window: int = 5) -> None:
    """Print, at each mark (the first epoch at or past it), eval success, its mean over the last
    ``window`` epochs (test episodes of one epoch are few, so one epoch's figure is noisy),
    training success over the same epochs, and wall time."""
    with open(run.metrics) as file:
        rows = [{k: float(v) for k, v in row.items() if v != ""} for row in csv.DictReader(file)]
    print(
        f"# {config.algo.value} on {config.env}, seed {config.seed}, "
        f"{config.threads} torch thread(s), {platform.processor() or platform.machine()}"
    )
    subgoals = "eval_subgoal_reached" in rows[0]
    print(
        f"{'env_steps':>10} {'eval_success':>12} {f'eval_last{window}':>10} {f'train_last{window}':>11} "
        f"{'wall_s':>8}" + (f" {'subgoal_reached':>15}" if subgoals else "")
    )
    for mark in marks:
        index = next((i for i, row in enumerate(rows) if row["env_steps"] >= mark), None)
        if index is None:
            print(f"{mark:>10} {'not reached':>12}")
            continue
        row, recent = rows[index], rows[max(0, index + 1 - window) : index + 1]
        eval_mean = sum(r["eval_success"] for r in recent) / len(recent)
        train_mean = sum(r["train_success"] for r in recent) / len(recent)
        figures = f"{row['eval_success']:>12.3f} {eval_mean:>10.3f} {train_mean:>11.3f} {row['wall_s']:>8.0f}"
        print(
            f"{int(row['env_steps']):>10} {figures}"
            + (f" {row['eval_subgoal_reached']:>15.3f}" if subgoals else "")
        )


if __name__ == "__main__":
    main()
