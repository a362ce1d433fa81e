r"""Sample efficiency: N seeds of one algorithm on one task, and how soon they learn.

Trains seeds 0..N-1 (in parallel where cores allow; a run left unfinished in ``--out``
resumes, a finished one is only read; the run directories are named as ``dtd sweep`` names
them, <env>-<algo>-s<seed>, so a sweep's directory serves as ``--out``) and prints, per seed
and as median [min, max], the env steps and wall time at which eval success first reached 0.5
and 0.9 (averaged over 3 epochs, see ``dtd.experiments.curves.SMOOTHING``) and the final eval success.
A benchmark, not a test.

    python benchmarks/sample_efficiency.py --env FetchPush-v4 --algo her --seeds 3 \
        --steps 200000 --out runs/se-push-her
"""

from __future__ import annotations

import argparse
import platform
from pathlib import Path

import numpy as np

from dtd.config import Algo, Preset, preset_config, with_settings
from dtd.experiments.curves import SMOOTHING, Curve, read_curve
from dtd.experiments.sweep import trial_name
from dtd.experiments.trials import Trial, TrialOutcome, run_local, sharing_cores
from dtd.training.components import usable_cores
from dtd.training.lifecycle import epochs_for_steps

LEVELS = (0.5, 0.9)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--env", default="FetchPush-v4")
    parser.add_argument("--algo", default="her", choices=[a.value for a in Algo])
    parser.add_argument("--preset", default="tuned", choices=[p.value for p in Preset])
    parser.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1")
    parser.add_argument("--steps", type=int, default=200_000, help="env steps per seed")
    parser.add_argument("--out", type=Path, required=True, help="one run directory per seed goes here")
    parser.add_argument("--parallel", type=int, default=None, help="runs at once (default: one per core)")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="any other setting, e.g. updates_per_cycle=80 or learner.batch_size=512 (JSON values)",
    )
    args = parser.parse_args()

    cores = usable_cores()
    workers = args.parallel or max(1, min(args.seeds, cores))
    base = with_settings(preset_config(Preset(args.preset), env=args.env, algo=Algo(args.algo)), args.set)
    base = sharing_cores(base, workers, cores)
    base = with_settings(base, [f"epochs={epochs_for_steps(base, args.steps)}"])
    trials = [
        Trial(config, args.out / trial_name(config))
        for config in (with_settings(base, [f"seed={seed}"]) for seed in range(args.seeds))
    ]

    def done(outcome: TrialOutcome) -> None:
        status = "done" if outcome.ok else f"FAILED\n{outcome.error}"
        print(f"{outcome.trial.name}: {status} ({outcome.wall_s:.0f} s)", flush=True)

    print(f"{len(trials)} run(s) of {args.steps} env steps, {workers} at once, into {args.out}", flush=True)
    outcomes = run_local(trials, workers, done)
    curves = {o.trial.name: read_curve(o.trial.run_dir) for o in outcomes if o.ok}
    settings = " ".join([f"preset={args.preset}", *args.set])
    print(f"# {args.algo} on {args.env}, {len(curves)} seed(s), {args.steps} env steps, settings {settings}, "
          f"{platform.machine()}, {cores} core(s), {workers} run(s) at once")  # fmt: skip
    print(summary(curves))


def summary(curves: dict[str, Curve]) -> str:
    """One line per run and the median [min, max] over runs."""
    heads = [f"steps to {level}" for level in LEVELS] + [f"wall to {level}" for level in LEVELS]
    lines = [
        f"{'run':<22} " + " ".join(f"{h:>16}" for h in heads) + f" {'final':>6} {'steps':>8} {'wall':>7}"
    ]
    table: dict[str, list[float]] = {h: [] for h in heads}
    finals, walls = [], []
    for name, curve in curves.items():
        cells = []
        for level in LEVELS:
            reached = curve.first_reaching(level)
            table[f"steps to {level}"].append(reached[0] if reached else np.inf)
            table[f"wall to {level}"].append(reached[1] if reached else np.inf)
        for head in heads:
            value = table[head][-1]
            cells.append(f"{'not reached':>16}" if np.isinf(value) else f"{value:>16.0f}")
        finals.append(curve.final_success)
        walls.append(float(curve.wall_s[-1]) if len(curve) else 0.0)
        steps = int(curve.env_steps[-1]) if len(curve) else 0
        lines.append(f"{name:<22} " + " ".join(cells) + f" {finals[-1]:>6.2f} {steps:>8} {walls[-1]:>6.0f}s")
    if len(curves) > 1:
        cells = [f"{_median_range(np.array(table[head])):>16}" for head in heads]
        lines.append(
            f"{'median [range]':<22} "
            + " ".join(cells)
            + f" {np.median(finals):>6.2f} {'':>8} {np.median(walls):>6.0f}s"
        )
    lines.append(
        f"(eval success averaged over {SMOOTHING} epochs; inf = not reached, counted as worse than any)"
    )
    return "\n".join(lines)


def _median_range(values: np.ndarray) -> str:
    def show(value: float) -> str:
        return "inf" if np.isinf(value) else f"{value / 1000:.0f}k" if value >= 10_000 else f"{value:.0f}"

    return f"{show(float(np.median(values)))} [{show(values.min())}-{show(values.max())}]"


if __name__ == "__main__":
    main()
