"""The ``dtd`` command line: every setting of :class:`dtd.config.TrainConfig` is an option.

Each command's module imports the library only when the command runs, so that ``dtd --help``
and a wrong option are answered without loading torch or MuJoCo.
"""

from __future__ import annotations

import sys

from dtd.cli.explaining import evaluate, explore, export, heatmap, render, report
from dtd.cli.options import REQUIRED_ENV_UNLESS_RESUMED, deferred, parse_command, settings_registry
from dtd.cli.training import plot, sweep, train
from dtd.config import Preset, preset_config
from dtd.errors import DtdError, MachineError, WorkerLost
from dtd.training.launch import INTERRUPTED_EXIT, LOST_WORKER_EXIT, JobPlace

DESCRIPTION = "Dot-to-Dot: train and explain goal-conditioned agents (DDPG, HER, DtD)."


def preset_named(argv: list[str]) -> Preset:
    """The ``--preset`` given in ``argv`` (the last one), else ``tuned``; a name that is not a
    preset is left for the parser to report."""
    preset = Preset.tuned
    for index, arg in enumerate(argv):
        name, _, value = arg.partition("=")
        if name != "--preset":
            continue
        value = value or (argv[index + 1] if index + 1 < len(argv) else "")
        if value in Preset.__members__:
            preset = Preset(value)
    return preset


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``dtd`` command."""
    args = sys.argv[1:] if argv is None else argv
    # Asked of the environment here alone: whether this process is a worker of a job.
    place = JobPlace.from_environment()
    # The preset supplies the defaults the other options override, so it is read first.
    preset = preset_config(preset_named(args))
    commands = {
        "train": deferred(train, preset, bound={"place": place, "invocation": tuple(args)}),
        "sweep": deferred(sweep, preset),
        "plot": deferred(plot),
        "eval": deferred(evaluate),
        "render": deferred(render),
        "heatmap": deferred(heatmap),
        "report": deferred(report),
        "explore": deferred(explore),
        "export": deferred(export),
    }
    try:
        if args[:1] == ["sweep"] and any(arg == "--algo" or arg.startswith("--algo=") for arg in args):
            raise DtdError("dtd sweep takes --algos (comma-separated), not --algo")
        if args[:1] == ["sweep"] and any(arg == "--workers" or arg.startswith("--workers=") for arg in args):
            raise DtdError(
                "dtd sweep takes --parallel N (trials at once), not --workers (dtd train's "
                "data-parallel workers of one run)"
            )
        registries = {
            "train": settings_registry(hints=REQUIRED_ENV_UNLESS_RESUMED),
            "sweep": settings_registry(omit=frozenset({"algo", "workers"})),
        }
        command = parse_command(commands, DESCRIPTION, args, registries)
        command()
    except DtdError as exc:
        print(f"dtd: error: {exc}", file=sys.stderr)
        sys.exit(2)
    except WorkerLost as exc:
        # A worker dtd started here leaves the report to its launcher, which knows who died.
        if not place.reports_for_itself:
            sys.exit(LOST_WORKER_EXIT)
        print(f"dtd: error: {exc}{_how_to_continue(args, exc)}", file=sys.stderr)
        sys.exit(1)
    except MachineError as exc:
        print(f"dtd: error: {exc}", file=sys.stderr)
        sys.exit(1)
    except KeyboardInterrupt as exc:
        if place.reports_for_itself:
            print(f"dtd: interrupted{_how_to_continue(args, exc)}", file=sys.stderr)
        sys.exit(INTERRUPTED_EXIT)


def _how_to_continue(args: list[str], interrupt: BaseException) -> str:
    run_dir = getattr(interrupt, "run_dir", None)
    if run_dir is not None:
        return f"; continue with dtd train --resume {run_dir}"
    if args[:1] == ["sweep"]:
        return "; run the same dtd sweep again to continue"
    return ""
