"""The functions of dtd's command line, configuration and training a new run passes through from
``dtd train`` to its first epoch: each of ``dtd.cli``, ``dtd.config`` and ``dtd.training``
entered at least once before the trainer starts, in the order first entered, with the depth of
its first call, and the chain of calls down to the agent's building and to the trainer. The run
stops there: nothing is trained.

    python benchmarks/start_path.py                          # FetchReach-v4, her
    python benchmarks/start_path.py --algo dtd --env FetchPush-v4
    PYTHONPATH=/path/to/other/checkout python benchmarks/start_path.py   # another version
"""

from __future__ import annotations

import argparse
import inspect
import sys
import tempfile
from pathlib import Path

PARTS = ("dtd/cli/", "dtd/config/", "dtd/training/")


class FirstEpoch(Exception):
    """Raised where the trainer starts: the path is complete."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="FetchReach-v4")
    parser.add_argument("--algo", default="her")
    args = parser.parse_args()

    import dtd.cli
    from dtd.training.components import build_agent
    from dtd.training.trainer import Trainer

    seen: dict[str, int] = {}
    chains: dict[str, list[str]] = {}
    depth = 0

    def named(code) -> str | None:  # type: ignore[no-untyped-def]
        """A function of the parts measured (not a class or module body), by file and name."""
        path = code.co_filename.replace("\\", "/")
        part = next((p for p in PARTS if p in path), None)
        if part is None or code.co_name.startswith("<") or not code.co_flags & inspect.CO_OPTIMIZED:
            return None
        return f"{part}{Path(path).stem}.{code.co_qualname}"

    def chain(frame) -> list[str]:  # type: ignore[no-untyped-def]
        names = []
        while frame is not None:
            names.append(named(frame.f_code) or "")
            frame = frame.f_back
        return [name.rsplit(".", 1)[-1] for name in reversed(names) if name]

    def trace(frame, event, arg):  # type: ignore[no-untyped-def]
        nonlocal depth
        if event == "call":
            depth += 1
            code = frame.f_code
            if code is build_agent.__code__ and "build_agent" not in chains:
                chains["build_agent"] = chain(frame)
            if code is Trainer.train.__code__:
                chains["Trainer.train"] = [*chain(frame.f_back), "Trainer.train"]
                raise FirstEpoch
            name = named(code)
            if name is not None:
                seen.setdefault(name, depth)
        elif event == "return":
            depth -= 1

    with tempfile.TemporaryDirectory() as folder:
        argv = ["train", "--env", args.env, "--algo", args.algo, "--epochs", "1", "--no-progress"]
        argv += ["--collector", "inline", "--run-dir", str(Path(folder) / "run")]
        sys.setprofile(trace)
        try:
            dtd.cli.main(argv)
        except FirstEpoch:
            pass
        finally:
            sys.setprofile(None)
    for name, first_depth in seen.items():
        print(f"{first_depth:3d}  {name}")
    for target, names in chains.items():
        print(f"to {target} ({len(names)} calls deep): {' -> '.join(names)}")
    print(f"{len(seen)} functions of {', '.join(p.strip('/') for p in PARTS)} before the first epoch")


if __name__ == "__main__":
    main()
