"""A markdown table of finished runs side by side, one row per run: env steps (and wall) at which
its 3-epoch mean eval success first met 0.5 and 0.9, its mean eval success over a window of
env steps, the mean of its last five evaluations, its budget and wall time.

    python benchmarks/curve_table.py --up-to 150000 --window 50000 150000 \\
        "s0 float32=runs/push-f32-s0" "s0 bfloat16=runs/push-bf16-s0"

A run is given as LABEL=RUN_DIR (a folder with config.json and metrics.csv), or as LABEL=FILE.csv
for a curve that ``peer_sb3.py`` wrote (env_steps, eval_success, wall_s: one row per evaluation,
each counted as an epoch); the curve is cut at --up-to env steps. The window's mean counts each
evaluation in (start, end], so it weighs how soon a run learns as well as where it ends, with less
of the noise of one epoch's 10 test episodes.

``--at-wall 12 20 50`` adds a second table: for each run, where it stood after that many minutes
of its wall: the env steps of its last evaluation by then and its 3-epoch mean eval success there
("-" before its first evaluation; the budget is marked "+" when the run ended sooner).

    python benchmarks/curve_table.py "dtd=runs/push-s100" "SB3=runs/peer-s0.csv" --at-wall 20 50
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from dtd.experiments.curves import Curve, read_curve

LEVELS = (0.5, 0.9)


def read_peer_curve(path: Path) -> Curve:
    """A curve ``peer_sb3.py`` wrote, its evaluations numbered as epochs."""
    with open(path, newline="") as file:
        rows = [
            [float(row[name]) for name in ("env_steps", "wall_s", "eval_success")]
            for row in csv.DictReader(file)
        ]
    table = np.array(rows, dtype=float).reshape(-1, 3)
    return Curve(np.arange(1, len(table) + 1, dtype=float), table[:, 0], table[:, 1], table[:, 2])


def reached(curve: Curve, level: float) -> str:
    first = curve.first_reaching(level)
    return "-" if first is None else f"{first[0] // 1000}k"


def window_mean(curve: Curve, start: float, end: float) -> float:
    inside = (curve.env_steps > start) & (curve.env_steps <= end)
    return float(curve.eval_success[inside].mean()) if inside.any() else float("nan")


def row(label: str, curve: Curve, start: float, end: float) -> str:
    last = curve.eval_success[-5:].mean() if len(curve) else float("nan")
    steps = f"{int(curve.env_steps[-1]) // 1000}k" if len(curve) else "-"
    wall = f"{curve.wall_s[-1] / 60:.0f} min" if len(curve) else "-"
    cells = [label, *(reached(curve, level) for level in LEVELS)]
    cells += [f"{window_mean(curve, start, end):.2f}", f"{last:.2f}", steps, wall]
    return "| " + " | ".join(cells) + " |"


def at_wall(curve: Curve, minutes: float) -> str:
    """'steps: success' of the last evaluation within ``minutes`` of wall."""
    inside = np.flatnonzero(curve.wall_s <= minutes * 60)
    if len(inside) == 0:
        return "-"
    last = inside[-1]
    ended = "+" if last == len(curve) - 1 and curve.wall_s[-1] < minutes * 60 else ""
    return f"{curve.env_steps[last] / 1000:.0f}k: {curve.smoothed()[last]:.2f}{ended}"


def wall_table(runs: list[tuple[str, Curve]], budgets: list[float]) -> list[str]:
    heads = " | ".join(f"after {minutes:g} min" for minutes in budgets)
    lines = [f"| run | {heads} |", "|---" * (len(budgets) + 1) + "|"]
    for label, curve in runs:
        lines.append("| " + " | ".join([label, *(at_wall(curve, minutes) for minutes in budgets)]) + " |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="+", metavar="LABEL=RUN_DIR|FILE.csv")
    parser.add_argument("--up-to", type=float, default=np.inf, help="cut each curve at these env steps")
    parser.add_argument("--window", type=float, nargs=2, metavar=("START", "END"), default=(0.0, np.inf))
    parser.add_argument(
        "--at-wall",
        type=float,
        nargs="+",
        metavar="MINUTES",
        default=[],
        help="also tabulate each run's env steps and success after these minutes of wall",
    )
    args = parser.parse_args()
    start, end = args.window
    last = min(end, args.up_to)
    window = (
        f"mean {start / 1000:.0f}k-{last / 1000:.0f}k"
        if np.isfinite(last)
        else f"mean after {start / 1000:.0f}k"
    )
    levels = " | ".join(f"to {level}" for level in LEVELS)
    print(f"| run | {levels} | {window} | last 5 | steps | wall |")
    print("|---" * (len(LEVELS) + 5) + "|")
    runs = []
    for given in args.runs:
        label, separator, where = given.partition("=")
        if not separator:
            parser.error(f"{given!r} is not LABEL=RUN_DIR or LABEL=FILE.csv")
        path = Path(where)
        curve = read_peer_curve(path) if path.suffix == ".csv" else read_curve(path)
        runs.append((label, curve.up_to(args.up_to)))
        print(row(label, runs[-1][1], start, end))
    if args.at_wall:
        print()
        print("\n".join(wall_table(runs, args.at_wall)))


if __name__ == "__main__":
    main()
