"""The ``dtd`` command line: every setting of :class:`dtd.config.TrainConfig` is an option.

Each command's module imports the library only when the command runs, so that ``dtd --help``
and a wrong option are answered without loading torch or MuJoCo.
"""

from __future__ import annotations

import contextlib
import signal
import sys
from collections.abc import Iterator

from dtd.cli.explaining import evaluate, explore, export, heatmap, render, report
from dtd.cli.options import REQUIRED_ENV_UNLESS_RESUMED, deferred, parse_command, settings_registry
from dtd.cli.training import plot, sweep, train
from dtd.config import Preset, preset_config
from dtd.errors import DtdError, MachineError, WorkerLost
from dtd.training.launch import INTERRUPTED_EXIT, LOST_WORKER_EXIT, JobPlace, watch_launcher

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
    # A worker started by dtd train --workers N ends with its launcher, never as an orphan.
    if place.launched_here and place.launcher is not None:
        watch_launcher(place.launcher)
    # The preset supplies the defaults the other options override, so it is read first.
    preset = preset_config(preset_named(args))
    commands = {
        "train": deferred(train, preset, bound={"place": place, "invocation": tuple(args)}),
        "sweep": deferred(sweep, preset, bound={"invocation": tuple(args)}),
        "plot": deferred(plot),
        "eval": deferred(evaluate),
        "render": deferred(render),
        "heatmap": deferred(heatmap),
        "report": deferred(report),
        "explore": deferred(explore),
        "export": deferred(export),
    }
    try:
        registries = {
            "train": settings_registry(hints=REQUIRED_ENV_UNLESS_RESUMED),
            "sweep": settings_registry(omit=frozenset({"algo", "workers"})),
        }
        command = parse_command(commands, DESCRIPTION, args, registries)
        with terminated_as_interrupted():
            command()
    except DtdError as exc:
        print(f"dtd: error: {exc}", file=sys.stderr)
        sys.exit(2)
    except WorkerLost as exc:
        # Asked now, not of the watch: the others may have stopped before it saw the launcher go.
        if place.launcher_gone():
            _report_orphaned(place, args, exc)
            sys.exit(INTERRUPTED_EXIT)
        # A worker dtd started here leaves the report to its launcher, which knows who died.
        if not place.reports_for_itself:
            sys.exit(LOST_WORKER_EXIT)
        print(f"dtd: error: {exc}{_how_to_continue(args, exc)}", file=sys.stderr)
        sys.exit(1)
    except MachineError as exc:
        print(f"dtd: error: {exc}", file=sys.stderr)
        sys.exit(1)
    except KeyboardInterrupt as exc:
        if place.launcher_gone():
            _report_orphaned(place, args, exc)
        elif place.reports_for_itself:
            print(f"dtd: interrupted{_how_to_continue(args, exc)}", file=sys.stderr)
        sys.exit(INTERRUPTED_EXIT)


def _report_orphaned(place: JobPlace, args: list[str], stop: BaseException) -> None:
    """Worker 0's one line for a job whose launcher ended (the others stop quietly)."""
    if place.reports:
        print(
            f"dtd: the launcher of this run's workers (pid {place.launcher}) ended, so its workers "
            f"stopped{_how_to_continue(args, stop)}",
            file=sys.stderr,
        )


def _how_to_continue(args: list[str], interrupt: BaseException) -> str:
    run_dir = getattr(interrupt, "run_dir", None)
    if run_dir is not None:
        return f"; continue with dtd train --resume {run_dir}"
    if args[:1] == ["sweep"]:
        return "; run the same dtd sweep again to continue"
    return ""


@contextlib.contextmanager
def terminated_as_interrupted() -> Iterator[None]:
    """SIGTERM (a scheduler's stop, ``kill``) handled as Ctrl-C while the block runs, by every
    command: the same one line, exit 130, the same clean-up. Once a stop is under way (by either
    signal), a further SIGTERM (a launcher stopping its workers) is ignored, so that it does not
    cut the clean-up short; a second Ctrl-C still interrupts it, as ever."""

    def interrupt(signum: int, frame: object) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    # Where Ctrl-C raises KeyboardInterrupt (not where a shell has it ignored), it does the same.
    ctrl_c = signal.getsignal(signal.SIGINT)
    if ctrl_c is signal.default_int_handler:
        signal.signal(signal.SIGINT, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        if ctrl_c is signal.default_int_handler:
            signal.signal(signal.SIGINT, ctrl_c)
