"""What the high level values: Q1(o, g, sub-goal) over a grid of sub-goals on the table.

For the Fetch block tasks the block and the goal are put where the user says, the
observation is read back from the simulator, and the high level's critic is evaluated at
every cell of a grid over the table top (at the block's height, or at several heights for
FetchPickAndPlace, whose goals may lie in the air). For a task whose goals are points on a
plane (x, y), such as Gymnasium-Robotics' mazes, the grid covers the goal box and the start and
goal are the task's own, from a seeded reset.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np

from dtd.agents.interface import Planner
from dtd.envs.time_feature import as_observed
from dtd.errors import ConfigError, EnvError
from dtd.figures import pyplot
from dtd.training.atomic import staged_file

DEFAULT_START = (1.15, 0.55)
"""The block's default place: near one corner of the table, as in the paper's figure."""
DEFAULT_GOAL = (1.45, 0.95)
"""The goal's default place: near the opposite corner."""


@dataclasses.dataclass(frozen=True)
class Table:
    """The top of the table in world coordinates (metres) and the resting block's height."""

    x: tuple[float, float]
    y: tuple[float, float]
    block_z: float


@dataclasses.dataclass(frozen=True)
class Heatmap:
    """The high level's values at each cell of one horizontal slice."""

    xs: np.ndarray
    ys: np.ndarray
    z: float | None
    """The slice's height (None: planar goals)."""
    values: np.ndarray
    """(len(ys), len(xs)): row i is y = ys[i], column j is x = xs[j]."""
    start: np.ndarray
    goal: np.ndarray
    subgoal: np.ndarray
    """The sub-goal the agent would choose here (its deterministic high-level action)."""


def table_of(env: gym.Env) -> Table:
    """The table of a Fetch task (a body ``table0`` with a box geom, a block ``object0``)."""
    unwrapped = env.unwrapped
    model, data = unwrapped.model, unwrapped.data
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "table0")
    block = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "object0:joint")
    if body < 0 or block < 0:
        raise EnvError(
            "heatmaps need a Fetch task with a block on a table (FetchPush, FetchPickAndPlace) or a task "
            "whose goals are points on a plane (x, y)"
        )
    geom = next(i for i in range(model.ngeom) if model.geom_bodyid[i] == body)
    centre, half = data.geom_xpos[geom], model.geom_size[geom]
    height = float(getattr(unwrapped, "height_offset", centre[2] + half[2]))
    return Table(
        (float(centre[0] - half[0]), float(centre[0] + half[0])),
        (float(centre[1] - half[1]), float(centre[1] + half[1])),
        height,
    )


def place_block_and_goal(
    env: gym.Env, start: Sequence[float], goal: Sequence[float], seed: int = 0
) -> dict[str, np.ndarray]:
    """Reset ``env``, put the block at ``start`` (x, y on the table) and the goal at ``goal``
    (x, y, or x, y, z), and return the observation read back from the simulator."""
    check_on_table(table_of(env), start, goal)
    env.reset(seed=seed)
    return put_block_and_goal(env, start, goal)


MAX_RESOLUTION = 200
"""Most grid cells along a side of a heatmap (200 x 200 values), for the command and the page."""

HIGHEST_ABOVE_TABLE = 0.5
"""How far above the resting block (m) a slice or a goal may lie: the tasks' goals lie within it."""


def check_resolution(resolution: int, name: str = "--resolution") -> None:
    """A :class:`ConfigError` for a grid finer than :data:`MAX_RESOLUTION` or coarser than 2."""
    if not 2 <= resolution <= MAX_RESOLUTION:
        raise ConfigError(f"{name} must lie in 2..{MAX_RESOLUTION}, got {resolution}")


def check_height(table: Table, z: float, name: str) -> None:
    """A :class:`ConfigError` for a height ``z`` (m) below the resting block or more than
    :data:`HIGHEST_ABOVE_TABLE` above it."""
    lowest, highest = table.block_z, table.block_z + HIGHEST_ABOVE_TABLE
    if not lowest <= z <= highest:
        raise ConfigError(
            f"{name} {z:.3f} lies outside {lowest:.3f}..{highest:.3f} m (the table to 0.5 m above it)"
        )


def check_placement(start: Sequence[float] | None, goal: Sequence[float] | None) -> None:
    """A :class:`ConfigError` for a block not placed by x,y or a goal not by x,y or x,y,z."""
    if start is not None and len(start) != 2:
        raise ConfigError(f"--start takes the block's x,y (2 numbers), got {len(start)}")
    if goal is not None and len(goal) not in (2, 3):
        raise ConfigError(f"--goal takes x,y or x,y,z (2 or 3 numbers), got {len(goal)}")


def check_on_table(
    table: Table,
    start: Sequence[float],
    goal: Sequence[float],
    names: tuple[str, str] = ("--start", "--goal"),
) -> None:
    """A :class:`ConfigError` when the block's or the goal's x, y lies off the table (each
    called by its name in ``names``)."""
    for name, point in zip(names, (start, goal), strict=True):
        x, y = point[0], point[1]
        if not (table.x[0] <= x <= table.x[1] and table.y[0] <= y <= table.y[1]):
            raise ConfigError(
                f"{name} {x:.3f},{y:.3f} lies off the table (x {table.x[0]:.2f}..{table.x[1]:.2f}, "
                f"y {table.y[0]:.2f}..{table.y[1]:.2f})"
            )


def put_block_and_goal(env: gym.Env, start: Sequence[float], goal: Sequence[float]) -> dict[str, np.ndarray]:
    """Put the block of a Fetch task at rest at ``start`` (x, y) and its goal at ``goal``, in the
    episode ``env`` holds now; the observation read back from the simulator."""
    table = table_of(env)
    unwrapped = env.unwrapped
    qpos = np.array([start[0], start[1], table.block_z, 1.0, 0.0, 0.0, 0.0])
    unwrapped._utils.set_joint_qpos(unwrapped.model, unwrapped.data, "object0:joint", qpos)
    unwrapped._utils.set_joint_qvel(unwrapped.model, unwrapped.data, "object0:joint", np.zeros(6))
    goal_z = goal[2] if len(goal) > 2 else table.block_z
    unwrapped.goal = np.array([goal[0], goal[1], goal_z], dtype=np.float64)
    mujoco.mj_forward(unwrapped.model, unwrapped.data)
    return as_observed(env, unwrapped._get_obs())


class PlacedStart(gym.Wrapper):
    """A Fetch block task whose episodes start with the block and the goal where given."""

    def __init__(self, env: gym.Env, start: Sequence[float], goal: Sequence[float]) -> None:
        super().__init__(env)
        check_on_table(table_of(env), start, goal)
        self.start, self.goal = tuple(start), tuple(goal)

    def reset(self, **kwargs):  # type: ignore[override]
        _, info = self.env.reset(**kwargs)
        return put_block_and_goal(self.env, self.start, self.goal), info


def value_slice(
    planner: Planner, observation: dict[str, np.ndarray], table: Table, z: float | None, resolution: int
) -> Heatmap:
    """The high level's values over a ``resolution`` x ``resolution`` grid of sub-goals
    (cell centres) covering the table top at height ``z`` (None: sub-goals are points x, y)."""
    if resolution < 2:
        raise ConfigError(f"--resolution must be at least 2, got {resolution}")
    xs = _centres(table.x, resolution)
    ys = _centres(table.y, resolution)
    grid_x, grid_y = np.meshgrid(xs, ys)
    columns = [grid_x.ravel(), grid_y.ravel()] + ([] if z is None else [np.full(grid_x.size, z)])
    candidates = np.stack(columns, axis=1)
    goal = np.asarray(observation["desired_goal"], dtype=np.float64)
    values = planner.subgoal_values(observation, goal, candidates).reshape(len(ys), len(xs))
    subgoal = planner.propose_subgoals(
        observation["observation"][None], observation["achieved_goal"][None], goal[None]
    )[0]
    return Heatmap(xs, ys, z, values, np.asarray(observation["achieved_goal"]), goal, subgoal)


def _centres(extent: tuple[float, float], count: int) -> np.ndarray:
    step = (extent[1] - extent[0]) / count
    return extent[0] + step * (np.arange(count) + 0.5)


def draw_heatmaps(
    columns: Sequence[tuple[str, Sequence[Heatmap]]], table: Table, path: Path, title: str
) -> Path:
    """Panels of heatmaps (label, slices per checkpoint) as an image (the format follows
    ``path``'s suffix)."""
    plt = pyplot()

    heights = max(len(slices) for _, slices in columns)
    # One checkpoint: its slices side by side; several: a column each, a row per height.
    single = len(columns) == 1
    rows, wide = (1, heights) if single else (heights, len(columns))
    size = (5.2 * wide, 4.6 * rows + 0.6)
    figure, axes = plt.subplots(rows, wide, figsize=size, squeeze=False, layout="constrained")
    extent = (table.x[0], table.x[1], table.y[0], table.y[1])
    for column, (label, slices) in enumerate(columns):
        for row, heat in enumerate(slices):
            axis = axes[0][row] if single else axes[row][column]
            image = axis.imshow(heat.values, origin="lower", extent=extent, cmap="viridis", aspect="equal")
            figure.colorbar(image, ax=axis, shrink=0.85, label="high-level value Q1(o, g, sub-goal)")
            planar = heat.z is None
            axis.plot(*heat.start[:2], "s", color="black", markersize=9, label="start" if planar else "block")
            axis.plot(*heat.goal[:2], "o", color="red", markersize=9, label="goal")
            axis.plot(
                *heat.subgoal[:2], "X", color="lime", markeredgecolor="black", markersize=11,
                label="chosen sub-goal" if planar else f"chosen sub-goal (z {heat.subgoal[2]:.2f} m)",
            )  # fmt: skip
            axis.set_xlabel("x (m, world frame)")
            axis.set_ylabel("y (m, world frame)")
            where = "sub-goals (x, y)" if planar else f"sub-goals at z = {heat.z:.3f} m"
            axis.set_title(f"{label}\n{where}", fontsize=10)
            axis.legend(loc="upper left", fontsize=7, framealpha=0.8)
        for row in range(len(slices), heights):
            (axes[0][row] if single else axes[row][column]).set_axis_off()
    figure.suptitle(title, fontsize=11)
    try:
        with staged_file(path, "the heatmap") as staging:
            figure.savefig(staging, dpi=110)
    finally:
        plt.close(figure)
    return path


def run_heatmaps(
    run_dir: Path,
    out: Path,
    checkpoints: Sequence[str] = ("first", "latest"),
    start: Sequence[float] | None = None,
    goal: Sequence[float] | None = None,
    heights: Sequence[float] | None = None,
    resolution: int = 60,
    seed: int = 0,
) -> tuple[Path, list[tuple[str, list[Heatmap]]]]:
    """Heatmaps of a dtd run's high level at each of ``checkpoints`` (a column each), drawn into
    ``out``. Heights default to the block's resting height, and for tasks whose goals may lie
    in the air (FetchPickAndPlace) also 10, 20 and 30 cm above it. A task with planar goals
    (x, y) is mapped over its goal box, from its own start and goal after a reset with
    ``seed``."""
    from dtd.training.atomic import ensure_writable
    from dtd.training.run_dir import RunDir, read_config
    from dtd.training.trained_run import load_run

    config = read_config(RunDir(Path(run_dir)))
    if not config.algo.sets_subgoals:
        raise ConfigError(
            f"heatmaps show a dtd run's high level; {run_dir} is a {config.algo.value} run, which has none"
        )
    if not checkpoints:
        raise ConfigError("--checkpoint names no checkpoint")
    check_resolution(resolution)
    check_placement(start, goal)
    ensure_writable(Path(out).parent, "the heatmap")
    rows: list[tuple[str, list[Heatmap]]] = []
    table = None
    for name in checkpoints:
        with load_run(Path(run_dir), name) as loaded:
            env, agent, spec = loaded.envs[0], loaded.agent.planner(), loaded.spec
            assert agent is not None  # a run whose agent sets sub-goals (checked above)
            if spec.goal_dim == 2 and spec.quaternion is None:
                if start is not None or goal is not None or heights is not None:
                    raise ConfigError(
                        f"--start, --goal and --heights place a Fetch task's block; {config.env} is mapped "
                        "from its own start and goal (--seed)"
                    )
                table = Table(
                    (spec.goal_low[0], spec.goal_high[0]), (spec.goal_low[1], spec.goal_high[1]), 0.0
                )
                observation, _ = env.reset(seed=seed)
                slices = [value_slice(agent, observation, table, None, resolution)]
            else:
                table = table_of(env)
                levels = heights
                if levels is None:
                    in_air = bool(getattr(env.unwrapped, "target_in_the_air", False))
                    levels = [table.block_z + lift for lift in ((0.0, 0.1, 0.2, 0.3) if in_air else (0.0,))]
                for z in levels:
                    check_height(table, z, "--heights")
                if goal is not None and len(goal) == 3:
                    check_height(table, goal[2], "--goal's z")
                placed = (start or DEFAULT_START, goal or DEFAULT_GOAL)
                observation = place_block_and_goal(env, *placed)
                slices = [value_slice(agent, observation, table, z, resolution) for z in levels]
            rows.append((f"after epoch {loaded.checkpoint.epoch} ({name})", slices))
    assert table is not None
    what = "start" if rows and rows[0][1][0].z is None else "block"
    title = f"{config.env}: the high level's value of each sub-goal\nfor the {what} (black) and goal (red)"
    return draw_heatmaps(rows, table, Path(out), title), rows
