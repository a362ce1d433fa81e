"""What ``dtd explore`` asks of a run, without the web: its epochs, the high level's value
map for a block and a goal placed by hand, and episodes played from such a placement.

One :class:`Explorer` owns one evaluation environment and one agent; the agent takes the
weights of whichever epoch is asked for from the run's agent-only snapshots
(``checkpoints/epochs/``, read again on every call: a run still training adds them). Its
methods touch the simulator and the renderer, so they are called from one thread at a time
(the server runs them all on one worker thread).
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import time
from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dtd.agents.segments import episode_plan
from dtd.config import EVAL_SEED, plain_data
from dtd.errors import CheckpointError, ConfigError, DtdError, EnvError, RunDirError
from dtd.experiments.curves import read_curve
from dtd.explain.heatmap import (
    PlacedStart,
    Table,
    check_height,
    check_on_table,
    check_resolution,
    place_block_and_goal,
    table_of,
    value_slice,
)
from dtd.training.checkpoint import Checkpoint
from dtd.training.components import build_acting
from dtd.training.run_dir import RunDir, read_config
from dtd.training.trained_run import on_the_cpu

MAP_RESOLUTION = 50
"""Cells along each side of the table in a value map, unless asked otherwise."""
KEPT_STATES = 16
"""Epochs whose weights stay in memory (a FetchPush dtd epoch is about 1.7 MB)."""
KEPT_VIDEOS = 20
"""Played episodes whose videos stay on disk; older ones are removed."""
FRAME_SIZE = 384
"""Frames of played episodes, in pixels (a multiple of 16, as H.264 wants)."""


class ExploreError(DtdError):
    """A request the explorer cannot answer; ``status`` is the HTTP status that says why."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


@dataclasses.dataclass(frozen=True)
class EpochSnapshot:
    """One epoch the explorer can show."""

    epoch: int
    env_steps: int
    eval_success: float | None
    path: Path


class Explorer:
    """A run's agent at any kept epoch, on an environment of its task."""

    def __init__(self, run_dir: Path | str, videos: Path, seed: int = EVAL_SEED) -> None:
        self.run = RunDir(Path(run_dir))
        self.config = read_config(self.run)
        self.videos = Path(videos)
        self.acting = build_acting(on_the_cpu(self.config), eval_seed=seed, eval_envs=1)
        self.env = self.acting.envs[0]
        self.agent = self.acting.agent
        self.spec = self.acting.spec
        self.rng = np.random.default_rng(seed)
        self.episode_seeds = itertools.count(seed)
        self.videos_made = itertools.count(1)
        self.states: OrderedDict[tuple[Path, int], Checkpoint] = OrderedDict()
        """The last epochs' networks read, without replay."""
        self.loaded: tuple[Path, int] | None = None
        self.renderer = None
        self.placement_table: Table | None = None
        """The table of a Fetch block task, where the block and the goal can be placed."""
        with contextlib.suppress(EnvError):
            self.placement_table = table_of(self.env)
        self.table = self.placement_table if self.config.algo.sets_subgoals else None
        """The table the high level's values are mapped over (a dtd run on a Fetch block task)."""
        self.no_map_reason = ""
        if not self.config.algo.sets_subgoals:
            self.no_map_reason = f"a {self.config.algo.value} run has no high level to map"
        elif self.table is None and self.spec.goal_dim == 2 and self.spec.quaternion is None:
            self.no_map_reason = (
                "this task's goals are points on a plane with no block to place by hand; `dtd heatmap` "
                "maps the high level's values from the task's own start and goal, and the plans and "
                "videos here show what it asks for"
            )
        elif self.table is None:
            self.no_map_reason = (
                "this task's goal is not a point on a table (for the Hand tasks it is the "
                "block's orientation, a unit quaternion), so there is no table to map the "
                "high level's values over; its plans and videos show what it asks for"
            )
        self.legacy = self._legacy_checkpoints()

    # -- what there is to see ------------------------------------------------------------
    def epochs(self) -> list[EpochSnapshot]:
        """The epochs there are snapshots of now, in order."""
        found = [EpochSnapshot(epoch, -1, None, path) for epoch, path in self.run.epoch_snapshots().items()]
        return found or list(self.legacy)

    def describe(self) -> dict[str, Any]:
        """The run, its task and its epochs, as the page needs them."""
        from dtd.explain.render import is_planar, marker_legend

        epochs = self.epochs()
        info: dict[str, Any] = {
            "run": str(self.run.root),
            "env": self.config.env,
            "algo": self.config.algo.value,
            "epochs_planned": self.config.epochs,
            "epochs": [snapshot.epoch for snapshot in epochs],
            "map": self.table is not None,
            "no_map_reason": self.no_map_reason,
            "placeable": self.placement_table is not None,
            "legend": marker_legend(
                self.spec.quaternion is not None, self.config.algo.sets_subgoals, is_planar(self.spec)
            ),
            "resolution": MAP_RESOLUTION,
            "progress": self._progress(),
        }
        if not epochs:
            info["waiting"] = (
                "no epoch has finished yet: the run keeps a snapshot of its agent after each epoch "
                "(checkpoints/epochs/), and the page shows them as they appear"
            )
        if self.placement_table is not None:
            table = self.placement_table
            info["table"] = {"x": table.x, "y": table.y, "block_z": table.block_z}
            info["goal_in_air"] = bool(getattr(self.env.unwrapped, "target_in_the_air", False))
        return info

    # -- the value map -------------------------------------------------------------------
    def value_map(
        self,
        epoch: int,
        block: tuple[float, float],
        goal: tuple[float, float, float | None],
        z: float | None = None,
        resolution: int = MAP_RESOLUTION,
    ) -> dict[str, Any]:
        """The high level's value of every cell of a ``resolution`` squared grid over the
        table at height ``z`` (default: the block's resting height) and the sub-goal it would
        choose, with the block at ``block`` and the goal at ``goal`` (its z None: on the table)."""
        began = time.perf_counter()
        if self.table is None:
            raise ExploreError(409, f"no value map for this run: {self.no_map_reason}")
        table = self.table
        height = table.block_z if z is None else z
        try:
            check_resolution(resolution, "resolution")
            check_height(table, height, "z")
        except ConfigError as exc:
            raise ExploreError(422, str(exc)) from exc
        goal_point = self._goal_point(goal)
        snapshot = self._use_epoch(epoch)
        self._check_on_table(block, goal_point)
        observation = place_block_and_goal(self.env, block, goal_point)
        planner = self.agent.planner()
        assert planner is not None  # a map is only offered for an agent that sets sub-goals
        heat = value_slice(planner, observation, table, height, resolution)
        row, column = np.unravel_index(int(np.argmax(heat.values)), heat.values.shape)
        return {
            "epoch": snapshot.epoch,
            "env_steps": snapshot.env_steps,
            "eval_success": snapshot.eval_success,
            "xs": heat.xs.tolist(),
            "ys": heat.ys.tolist(),
            "z": heat.z,
            "values": heat.values.astype(float).round(6).tolist(),
            "block": heat.start.astype(float).tolist(),
            "goal": heat.goal.astype(float).tolist(),
            "subgoal": heat.subgoal.astype(float).tolist(),
            "highest": [float(heat.xs[column]), float(heat.ys[row]), heat.z],
            "value_range": [float(heat.values.min()), float(heat.values.max())],
            "compute_ms": round((time.perf_counter() - began) * 1000, 1),
        }

    # -- episodes ------------------------------------------------------------------------
    def play(
        self,
        epoch: int,
        block: tuple[float, float] | None = None,
        goal: tuple[float, float, float | None] | None = None,
    ) -> dict[str, Any]:
        """Render one deterministic episode of ``epoch``'s agent, from the block and goal given
        (Fetch block tasks) or from the task's own random start; the video's file name and the
        episode's plan."""
        from dtd.explain.render import SceneRenderer, camera_for, render_episode, write_video

        snapshot = self._use_epoch(epoch)
        env = self.env
        if block is not None or goal is not None:
            if self.placement_table is None:
                raise ExploreError(409, "this task's block and goal cannot be placed by hand")
            if block is None or goal is None:
                raise ExploreError(422, "give both the block and the goal, or neither")
            goal_point = self._goal_point(goal)
            self._check_on_table(block, goal_point)
            env = PlacedStart(self.env, block, goal_point)
        if self.renderer is None:
            self.renderer = SceneRenderer(self.env, FRAME_SIZE, FRAME_SIZE, camera_for(self.spec.env_id))
        self.env.reset(seed=next(self.episode_seeds))
        planner = self.agent.planner()
        bounds = planner.bounds if planner is not None else None
        plan_of = planner.plan if planner is not None else None
        rendered = render_episode(env, self.agent, self.spec, self.renderer, self.rng, bounds, plan_of)
        name = f"episode-{next(self.videos_made)}.mp4"
        write_video(rendered.frames, self.videos / name)
        self._forget_old_videos()
        plan = plan_of(rendered.episode)[0] if plan_of else episode_plan(rendered.episode, 0, None)
        return {"epoch": snapshot.epoch, "video": name, "plan": plain_data(plan)}

    def close(self) -> None:
        if self.renderer is not None:
            self.renderer.close()
        self.acting.close()

    # -- inside ----------------------------------------------------------------------------
    def _check_on_table(self, block: Sequence[float], goal: Sequence[float]) -> None:
        assert self.placement_table is not None, "called only where the block and the goal can be placed"
        try:
            check_on_table(self.placement_table, block, goal, ("the block", "the goal"))
        except ConfigError as exc:
            raise ExploreError(422, str(exc)) from exc

    def _goal_point(self, goal: tuple[float, float, float | None]) -> tuple[float, ...]:
        x, y, z = goal
        if z is None:
            return (x, y)
        table = self.placement_table
        assert table is not None, "called only where the block and the goal can be placed"
        try:
            check_height(table, z, "the goal's z")
        except ConfigError as exc:
            raise ExploreError(422, str(exc)) from exc
        return (x, y, z)

    def _use_epoch(self, epoch: int) -> EpochSnapshot:
        snapshots = {snapshot.epoch: snapshot for snapshot in self.epochs()}
        snapshot = snapshots.get(epoch)
        if snapshot is None:
            kept = ", ".join(map(str, snapshots)) or "none yet"
            raise ExploreError(404, f"no snapshot of epoch {epoch} in this run (epochs kept: {kept})")
        try:
            key = (snapshot.path, snapshot.path.stat().st_mtime_ns)
        except OSError as exc:  # removed since it was listed (a run started again with --force)
            raise ExploreError(404, f"the snapshot of epoch {epoch} is gone ({exc.strerror})") from exc
        if key not in self.states:
            stored = Checkpoint.read(snapshot.path)
            stored.check_fits(self.config, self.spec, snapshot.path)
            self.states[key] = dataclasses.replace(stored, agent=stored.acting_agent_state())
            while len(self.states) > KEPT_STATES:
                self.states.popitem(last=False)
        self.states.move_to_end(key)
        stored = self.states[key]
        if self.loaded != key:
            stored.load_agent(self.agent, snapshot.path)
            self.loaded = key
        return dataclasses.replace(snapshot, env_steps=stored.env_steps, eval_success=stored.eval_success)

    def _legacy_checkpoints(self) -> list[EpochSnapshot]:
        """For runs made before agent-only snapshots were kept: first.pt and latest.pt."""
        if self.run.epoch_snapshots():
            return []
        found: dict[int, EpochSnapshot] = {}
        for path in (self.run.first, self.run.latest):
            if not path.is_file():
                continue
            try:
                stored = Checkpoint.read(path)
            except CheckpointError:
                continue
            found[stored.epoch] = EpochSnapshot(stored.epoch, stored.env_steps, stored.eval_success, path)
        return [found[epoch] for epoch in sorted(found)]

    def _progress(self) -> dict[str, Any] | None:
        """The last finished epoch in metrics.csv (a run may still be training)."""
        try:
            curve = read_curve(self.run.root)
        except RunDirError:  # not a metrics file dtd wrote (or caught half-written): say nothing
            return None
        if len(curve) == 0:
            return None
        return {"epoch": int(curve.epoch[-1]), "env_steps": int(curve.env_steps[-1])}

    def _forget_old_videos(self) -> None:
        videos = sorted(self.videos.glob("episode-*.mp4"), key=lambda path: path.stat().st_mtime_ns)
        for path in videos[:-KEPT_VIDEOS]:
            path.unlink(missing_ok=True)
