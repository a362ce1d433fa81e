"""Torch threads beside other busy processes: what one learner update costs (3x256 networks,
FetchPush's sizes) with 1 and 2 torch threads under each OpenMP wait policy, on a quiet machine
and beside processes that each keep one core busy; optionally a whole short training epoch.

Every setting runs in a fresh process: the OpenMP runtime reads its settings once, when torch
is loaded. "dtd" is what the library itself chooses (it is imported before torch); the other
rows set the environment by hand and import torch first.

    python benchmarks/contention.py                      # updates, quiet and beside 1 busy core
    python benchmarks/contention.py --busy 0 1 2 --train # ... and a 5-cycle FetchPush epoch
    python benchmarks/contention.py --precision bfloat16 --train
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

SETTINGS = {
    # name: (torch threads, environment variables; None: the variable is removed)
    "1 thread": (1, {"OMP_WAIT_POLICY": None, "GOMP_SPINCOUNT": None}),
    "2 threads, OpenMP's default waiting": (2, {"OMP_WAIT_POLICY": None, "GOMP_SPINCOUNT": None}),
    "2 threads, OMP_WAIT_POLICY=PASSIVE": (2, {"OMP_WAIT_POLICY": "PASSIVE", "GOMP_SPINCOUNT": None}),
    "2 threads, OMP_WAIT_POLICY=ACTIVE": (2, {"OMP_WAIT_POLICY": "ACTIVE", "GOMP_SPINCOUNT": None}),
    "2 threads, GOMP_SPINCOUNT=10000": (2, {"OMP_WAIT_POLICY": None, "GOMP_SPINCOUNT": "10000"}),
    "2 threads, GOMP_SPINCOUNT=100000": (2, {"OMP_WAIT_POLICY": None, "GOMP_SPINCOUNT": "100000"}),
    "dtd, --threads 0": (0, {"OMP_WAIT_POLICY": None, "GOMP_SPINCOUNT": None}),
}

SPIN = "while True: pass"


def time_updates(
    threads: int, batch: int, updates: int, through_dtd: bool, precision: str = "float32"
) -> dict[str, float]:
    """In this process: ms per update (median over blocks of 10) of a fresh learner."""
    if through_dtd:
        import dtd  # noqa: F401  (imported before torch, as the command line does)
    import numpy as np
    import torch

    from dtd.agents.ddpg import DDPGLearner
    from dtd.agents.networks import BoxActionHead
    from dtd.config import LearnerConfig
    from dtd.training.components import resolved_threads

    torch.set_num_threads(resolved_threads(threads))
    from updates import ACT, GOAL, OBS, random_batch  # benchmarks/updates.py: FetchPush's sizes

    rng = np.random.default_rng(0)
    config = LearnerConfig(batch_size=batch)
    dtype = getattr(torch, precision)
    learner = DDPGLearner(OBS, GOAL, ACT, BoxActionHead(1.0), config, 0.98, (-1.0, 0.0), precision=dtype)
    batches = [random_batch(rng, batch) for _ in range(20)]
    for b in batches[:10]:
        learner.update(b)
    blocks = []
    for start in range(0, updates, 10):
        began = time.perf_counter()
        for index in range(start, min(start + 10, updates)):
            learner.update(batches[index % len(batches)])
        blocks.append((time.perf_counter() - began) / min(10, updates - start))
    return {"ms": 1000 * float(np.median(blocks)), "threads": torch.get_num_threads()}


def child_environment(overrides: dict[str, str | None]) -> dict[str, str]:
    env = dict(os.environ)
    for name, value in overrides.items():
        if value is None:
            env.pop(name, None)
        else:
            env[name] = value
    return env


def run_child(name: str, batch: int, updates: int, repeats: int, precision: str) -> dict[str, float]:
    """The median over ``repeats`` fresh processes of :func:`one_child`."""
    import statistics

    runs = [one_child(name, batch, updates, precision) for _ in range(repeats)]
    return {"ms": statistics.median(run["ms"] for run in runs), "threads": runs[0]["threads"]}


def one_child(name: str, batch: int, updates: int, precision: str) -> dict[str, float]:
    threads, overrides = SETTINGS[name]
    command = [
        sys.executable,
        __file__,
        "--child",
        json.dumps([threads, batch, updates, name.startswith("dtd"), precision]),
    ]
    done = subprocess.run(
        command, capture_output=True, text=True, env=child_environment(overrides), check=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def run_epoch(name: str, workdir: str, precision: str) -> float:
    """Seconds of `dtd train` for one 5-cycle FetchPush dtd epoch with this setting."""
    threads, overrides = SETTINGS[name]
    run_dir = os.path.join(workdir, f"epoch-{time.monotonic_ns()}")
    command = [sys.executable, "-m", "dtd", "train", "--env", "FetchPush-v4", "--algo", "dtd",
               "--epochs", "1", "--n-cycles", "5", "--threads", str(max(threads, 0)),
               "--precision", precision, "--no-progress", "--run-dir", run_dir]  # fmt: skip
    env = child_environment(overrides)
    done = subprocess.run(command, capture_output=True, text=True, env=env, check=True)
    return float(json.loads(done.stdout.strip().splitlines()[-1])["wall_s"])


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--busy", type=int, nargs="+", default=[0, 1], help="busy processes beside (each a core)"
    )
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--updates", type=int, default=400)
    parser.add_argument("--repeats", type=int, default=3, help="fresh processes per setting (median)")
    parser.add_argument("--only", nargs="+", choices=sorted(SETTINGS), help="these settings only")
    parser.add_argument("--train", action="store_true", help="also time a 5-cycle FetchPush dtd epoch")
    parser.add_argument("--precision", choices=["float32", "bfloat16"], default="float32")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(time_updates(*json.loads(args.child))))
        return

    import tempfile

    omp = os.environ.get("OMP_NUM_THREADS", "unset")
    print(f"# {platform.machine()}, {os.cpu_count()} cores, batch {args.batch}, {args.updates} updates "
          f"per setting, {args.precision}; OMP_NUM_THREADS={omp}")  # fmt: skip
    names = [name for name in SETTINGS if not args.only or name in args.only or name == "1 thread"]
    results: dict[tuple[str, int], dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as workdir:
        for busy in args.busy:
            spinners = [subprocess.Popen([sys.executable, "-c", SPIN]) for _ in range(busy)]
            try:
                time.sleep(0.5)
                for name in names:
                    figures = run_child(name, args.batch, args.updates, args.repeats, args.precision)
                    if args.train:
                        figures["epoch_s"] = run_epoch(name, workdir, args.precision)
                    results[name, busy] = figures
                    extra = f", epoch {figures['epoch_s']:.1f} s" if args.train else ""
                    print(f"busy {busy}  {name:<38} {figures['ms']:8.2f} ms/update "
                          f"({int(figures['threads'])} thread(s)){extra}", flush=True)  # fmt: skip
            finally:
                for spinner in spinners:
                    spinner.kill()
                    spinner.wait()
    print("\n# against 1 thread under the same load (update; epoch)")
    for busy in args.busy:
        base = results["1 thread", busy]
        for name in names:
            figures = results[name, busy]
            epoch = f"; {figures['epoch_s'] / base['epoch_s']:.2f}x" if args.train else ""
            print(f"busy {busy}  {name:<38} {figures['ms'] / base['ms']:6.2f}x{epoch}")


if __name__ == "__main__":
    main()
