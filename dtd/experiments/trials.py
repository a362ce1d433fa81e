"""Many training runs ("trials") at once: in local processes, or as tasks of a Ray cluster.

A trial is a configuration (its ``epochs`` the budget) and a run directory. Run again on the
same directories, finished trials are left alone and interrupted ones resume from their last
checkpoint (:func:`dtd.training.lifecycle.train_to_end`). A failing trial is reported with its traceback
and does not stop the others. Interrupted (Ctrl-C, SIGTERM), a runner stops its running trials
at once (each keeps its last finished epoch) and starts no other.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import multiprocessing
import os
import signal
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path

from dtd.config import Collection, TrainConfig, settings_apart
from dtd.errors import DtdError
from dtd.training.launch import on_parent_gone

LOG_NAME = "train.log"
"""File in a trial's run directory that receives what its training writes to stderr."""

POLL_S = 2.0
"""Seconds between calls of a runner's ``on_wait`` while trials are running."""


@dataclasses.dataclass(frozen=True)
class Trial:
    """One training run of a sweep: ``config`` trained to ``config.epochs`` in ``run_dir``."""

    config: TrainConfig
    run_dir: Path
    final_episodes: int = 0
    """Evaluate the last checkpoint over this many episodes once trained (0: not), saved as
    RUN/eval-latest.json (:func:`dtd.training.trained_run.final_evaluation`)."""

    given: frozenset[str] | None = None
    """The settings the sweep was given, by their names in :func:`dtd.config.flat_items`: a
    trial resumed takes these from ``config`` and keeps its own others. None: those of
    ``config`` that differ from its preset's defaults (:func:`dtd.training.lifecycle.resumed_config`)."""

    @property
    def name(self) -> str:
        return self.run_dir.name

    def with_config(self, config: TrainConfig) -> Trial:
        """This trial with ``config``, the settings in which it differs from the trial's own
        counted as given."""
        if self.given is None:
            return dataclasses.replace(self, config=config)
        changed = settings_apart(config, self.config)
        return dataclasses.replace(self, config=config, given=self.given | changed)


@dataclasses.dataclass(frozen=True)
class TrialOutcome:
    """How a trial ended: ``error`` holds the traceback of a failure, else None."""

    trial: Trial
    error: str | None
    wall_s: float
    """Seconds this call spent on the trial (close to 0 for one finished before)."""
    interrupted: bool = False
    """Stopped by an interrupt before its end (or never started): it resumes when run again."""

    @property
    def ok(self) -> bool:
        return self.error is None and not self.interrupted


RAY_STOP_S = 30.0
"""Seconds an interrupted sweep waits for its running Ray tasks to stop."""

OnDone = Callable[[TrialOutcome], None]
OnWait = Callable[[], None]


def sharing_cores(config: TrainConfig, workers: int, cores: int) -> TrainConfig:
    """``config`` for one of ``workers`` trials running at once on ``cores`` cores: automatic
    torch threads become an equal share of the cores, and episodes are collected inline (a
    collecting process per trial would only add processes fighting for the same cores).
    Settings given explicitly are kept."""
    if workers <= 1:
        return config
    changes: dict[str, object] = {}
    if config.threads == 0:
        changes["threads"] = max(1, cores // workers)
    if config.collector is Collection.auto:
        changes["collector"] = Collection.inline
    return dataclasses.replace(config, **changes)


def run_trial(trial: Trial) -> TrialOutcome:
    """Train ``trial`` to its last epoch (resuming, or leaving a finished run); never raises.
    Interrupted, the trial stops where it is (its last finished epoch is kept) and the outcome
    says so."""
    from dtd.training.lifecycle import train_to_end
    from dtd.training.trained_run import final_evaluation

    start = time.perf_counter()
    try:
        trial.run_dir.mkdir(parents=True, exist_ok=True)
        # Each trial's epoch lines and warnings go to its own log, not into the sweep's display.
        with open(trial.run_dir / LOG_NAME, "a") as log, contextlib.redirect_stderr(log):
            train_to_end(trial.config, trial.run_dir, trial.given)
            if trial.final_episodes:
                final_evaluation(trial.run_dir, trial.final_episodes)
    except KeyboardInterrupt:
        return TrialOutcome(trial, None, time.perf_counter() - start, interrupted=True)
    except Exception:
        return TrialOutcome(trial, traceback.format_exc(), time.perf_counter() - start)
    return TrialOutcome(trial, None, time.perf_counter() - start)


def run_local(
    trials: Sequence[Trial],
    workers: int,
    on_done: OnDone | None = None,
    on_wait: OnWait | None = None,
) -> list[TrialOutcome]:
    """Run ``trials`` in a pool of ``workers`` processes; outcomes in the order of ``trials``.

    ``on_done`` is called in this process as each trial ends, ``on_wait`` every
    :data:`POLL_S` seconds meanwhile. Even one worker is a process of its own, so that a trial
    that crashes its interpreter is reported like any other failure. Interrupted (a
    KeyboardInterrupt here, or SIGINT to the whole process group as a terminal sends it), the
    running trials stop, the queued ones never start, and the KeyboardInterrupt is raised again
    once the workers are done.
    """
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    outcomes: dict[int, TrialOutcome] = {}
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_start_worker, initargs=(os.getpid(),)
    ) as pool:
        futures = {pool.submit(_run_in_worker, trial): index for index, trial in enumerate(trials)}
        pending = set(futures)
        try:
            _collect(futures, pending, trials, outcomes, on_done, on_wait)
        except KeyboardInterrupt:
            for future in pending:
                future.cancel()
            # Trials already handed to a worker's queue cannot be cancelled: the workers,
            # interrupted, answer them at once without training.
            for child in multiprocessing.active_children():
                with contextlib.suppress(ProcessLookupError):
                    os.kill(child.pid, signal.SIGINT)
            raise
    return [outcomes[index] for index in range(len(trials))]


def _collect(
    futures: dict[concurrent.futures.Future, int],
    pending: set[concurrent.futures.Future],
    trials: Sequence[Trial],
    outcomes: dict[int, TrialOutcome],
    on_done: OnDone | None,
    on_wait: OnWait | None,
) -> None:
    """Wait for the ``pending`` futures (taking them out as they end), each outcome into
    ``outcomes``."""
    while pending:
        done, _ = concurrent.futures.wait(
            pending, timeout=POLL_S, return_when=concurrent.futures.FIRST_COMPLETED
        )
        for future in done:
            pending.discard(future)
            index = futures[future]
            try:
                outcomes[index] = future.result()
            except Exception:  # the worker process itself died
                outcomes[index] = TrialOutcome(trials[index], traceback.format_exc(), 0.0)
            if on_done is not None:
                on_done(outcomes[index])
        if on_wait is not None:
            on_wait()


_stopping = threading.Event()
"""Set in a pool's worker once it was interrupted: it starts no further trial."""

_training = threading.Event()
"""Set in a pool's worker while it trains a trial."""


def _run_in_worker(trial: Trial) -> TrialOutcome:
    """:func:`run_trial` in a pool's worker, unless the worker was interrupted before."""
    if _stopping.is_set():
        return TrialOutcome(trial, None, 0.0, interrupted=True)
    _training.set()
    try:
        return run_trial(trial)
    finally:
        _training.clear()


def _start_worker(parent: int) -> None:
    """In a pool's worker: the first interrupt stops the trial it trains (a KeyboardInterrupt,
    as in ``dtd train``) and every later trial is answered without training; and the process
    ends as soon as ``parent`` is gone, so that a killed sweep leaves no trial training on (a
    sweep run again would resume the same run directory in a second process)."""

    def interrupt(signum: int, frame: object) -> None:
        first = not _stopping.is_set()
        _stopping.set()
        if first and _training.is_set():
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    on_parent_gone(parent, lambda: os._exit(1), poll_s=0.25)


def run_ray(
    trials: Sequence[Trial],
    address: str,
    on_done: OnDone | None = None,
    on_wait: OnWait | None = None,
) -> list[TrialOutcome]:
    """Run ``trials`` as Ray tasks; outcomes in the order of ``trials``.

    ``address``: ``auto`` joins the Ray cluster running on this machine's network (or, if
    none is found, starts a local one for these trials), ``local`` always starts a local one,
    anything else is a cluster address (``ray://host:10001`` or ``host:6379``). Where Ray is
    already initialised in this process, that session is used as it is. Each task asks Ray
    for as many CPUs as its trial has torch threads, so Ray places no more trials on a node
    than it has cores. Run directories must lie where every node can reach them.
    """
    ray = import_ray()
    started_here = not ray.is_initialized()
    if started_here:
        # Ray installs a SIGTERM handler of its own; the caller's (a sweep's stop) is kept.
        on_terminate = signal.getsignal(signal.SIGTERM)
        _init_ray(ray, address)
        if signal.getsignal(signal.SIGTERM) != on_terminate and on_terminate is not None:
            signal.signal(signal.SIGTERM, on_terminate)
    try:
        remote = ray.remote(run_trial)
        refs = {
            remote.options(num_cpus=max(1, trial.config.threads)).remote(trial): index
            for index, trial in enumerate(trials)
        }
        outcomes: dict[int, TrialOutcome] = {}
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1, timeout=POLL_S)
                for ref in done:
                    index = refs[ref]
                    try:
                        outcomes[index] = ray.get(ref)
                    except Exception:  # the task or its worker died
                        outcomes[index] = TrialOutcome(trials[index], traceback.format_exc(), 0.0)
                    if on_done is not None:
                        on_done(outcomes[index])
                if on_wait is not None:
                    on_wait()
        except KeyboardInterrupt:
            # Queued tasks are dropped; running ones get a KeyboardInterrupt, keep their last
            # finished epoch and are waited for (a little) so that none writes on after the sweep.
            for ref in pending:
                ray.cancel(ref)
            ray.wait(pending, num_returns=len(pending), timeout=RAY_STOP_S)
            raise
        return [outcomes[index] for index in range(len(trials))]
    finally:
        if started_here:
            ray.shutdown()


def import_ray():
    """The ray module, or a :class:`DtdError` that says how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise DtdError("--ray needs Ray, an optional extra: pip install 'dtd[ray]'") from exc
    return ray


def _init_ray(ray, address: str) -> None:
    if address == "local":
        ray.init()
    elif address == "auto":
        try:
            ray.init(address="auto")
        except ConnectionError:  # no cluster running: one on this machine, for these trials
            ray.init()
    else:
        try:
            ray.init(address=address)
        except ConnectionError as exc:
            raise DtdError(f"no Ray cluster answers at {address}: {exc}") from exc


def trials_root(path: Path) -> Path:
    """``path`` made absolute, as every worker (on any node) must read it the same way."""
    return Path(path).expanduser().resolve()
