"""Rendering episodes of a trained run headlessly: the goal as a red dot (or, for a rotation
goal, the environment's own ghost block), the current sub-goal as a green dot (or a green
ghost block), an MP4 per episode and a strip of key frames.

Frames are drawn with a ``mujoco.Renderer`` of the environment's own model and data (EGL on a
machine without a display) from the environment's default camera; the markers are extra
geoms added to the scene, so :meth:`SceneRenderer.project` can say where they land.
"""

from __future__ import annotations

import contextlib
import dataclasses
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from dtd.agents.interface import Agent
from dtd.agents.records import Episodes
from dtd.agents.segments import episode_plan
from dtd.config import EVAL_SEED
from dtd.envs.spec import EnvSpec
from dtd.figures import pyplot
from dtd.training.rollout import run_episodes

GOAL_RGBA = (0.9, 0.05, 0.05, 1.0)
SUBGOAL_RGBA = (0.05, 0.85, 0.05, 1.0)
PLANAR_SUBGOAL_RGBA = (0.1, 0.35, 1.0, 1.0)
"""The sub-goal's dot where goals are points on a plane: blue, since the mazes' ball is green."""
GHOST_SUBGOAL_RGBA = (0.1, 0.9, 0.1, 0.5)
DOT_RADIUS = 0.025
GHOST_HALF_SIZE = 0.025
"""Half the edge of the Hand task's block."""
GHOST_BESIDE = np.array([0.0, 0.09, 0.0])
"""Where the sub-goal's ghost block sits relative to the goal's, when the task ignores the
block's position (the rotation tasks show the goal's ghost 15 cm beside the hand)."""
FALLBACK_CAMERA = {"distance": 2.0, "azimuth": 135.0, "elevation": -20.0, "lookat": np.zeros(3)}
TASK_CAMERAS = {
    # Closer than the environments' own default (2.5 m away): the table fills the frame.
    "Fetch": {"distance": 1.2, "azimuth": 160.0, "elevation": -35.0, "lookat": np.array([1.3, 0.75, 0.45])},
    # A little further out than the default, so that the ghost blocks beside the hand fit.
    "Hand": {"distance": 0.6, "azimuth": 55.0, "elevation": -25.0, "lookat": np.array([1.05, 0.93, 0.17])},
    # From above the maze's centre, the whole of a small maze in view.
    "PointMaze": {"distance": 7.0, "azimuth": 90.0, "elevation": -90.0, "lookat": np.array([0.0, 0.0, 0.0])},
    "AntMaze": {"distance": 10.0, "azimuth": 90.0, "elevation": -90.0, "lookat": np.array([0.0, 0.0, 0.0])},
}


def camera_for(env_id: str) -> dict[str, Any] | None:
    """The camera frames of ``env_id`` are drawn from (None: the environment's default)."""
    name = env_id.split(":")[-1]
    return next((camera for prefix, camera in TASK_CAMERAS.items() if name.startswith(prefix)), None)


@dataclasses.dataclass(frozen=True)
class Marker:
    """A sphere (``quaternion`` None) or a box with that orientation, added to a frame."""

    position: np.ndarray
    rgba: tuple[float, float, float, float]
    size: float
    quaternion: np.ndarray | None = None


class SceneRenderer:
    """Offscreen frames of one environment from its default camera, with extra markers."""

    def __init__(
        self, env: gym.Env, width: int = 480, height: int = 480, camera: dict[str, Any] | None = None
    ) -> None:
        unwrapped = env.unwrapped
        self.env = env
        self.model, self.data = unwrapped.model, unwrapped.data
        self.model.vis.global_.offwidth = max(self.model.vis.global_.offwidth, width)
        self.model.vis.global_.offheight = max(self.model.vis.global_.offheight, height)
        self.width, self.height = width, height
        self.renderer = mujoco.Renderer(self.model, height=height, width=width)
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        renderer = getattr(unwrapped, "mujoco_renderer", None)
        config = camera or getattr(renderer, "default_cam_config", None) or FALLBACK_CAMERA
        for key, value in config.items():
            if isinstance(value, np.ndarray):
                getattr(self.camera, key)[:] = value
            else:
                setattr(self.camera, key, value)

    def render(self, markers: Sequence[Marker] = ()) -> np.ndarray:
        """The current state as an (height, width, 3) uint8 image, with ``markers``."""
        callback = getattr(self.env.unwrapped, "_render_callback", None)
        if callback is not None:
            callback()  # the environment places its own goal display (site or ghost block)
        self.renderer.update_scene(self.data, camera=self.camera)
        scene = self.renderer.scene
        for marker in markers:
            if scene.ngeom >= scene.maxgeom:
                break
            matrix = np.eye(3).ravel()
            kind, size = mujoco.mjtGeom.mjGEOM_SPHERE, np.array([marker.size, 0.0, 0.0])
            if marker.quaternion is not None:
                matrix = np.zeros(9)
                mujoco.mju_quat2Mat(matrix, np.asarray(marker.quaternion, dtype=np.float64))
                kind, size = mujoco.mjtGeom.mjGEOM_BOX, np.full(3, marker.size)
            mujoco.mjv_initGeom(
                scene.geoms[scene.ngeom],
                type=kind,
                size=size,
                pos=np.asarray(marker.position, dtype=np.float64),
                mat=matrix,
                rgba=np.asarray(marker.rgba, dtype=np.float32),
            )
            scene.ngeom += 1
        return self.renderer.render().copy()

    def project(self, point: np.ndarray) -> tuple[float, float]:
        """Pixel (column, row) of a world point in the last rendered frame (row 0 at the top)."""
        # The scene holds a camera per eye; a mono image is drawn from their average.
        camera = mujoco.mjv_averageCamera(self.renderer.scene.camera[0], self.renderer.scene.camera[1])
        forward, up = np.array(camera.forward), np.array(camera.up)
        right = np.cross(forward, up)
        offset = np.asarray(point, dtype=np.float64) - np.array(camera.pos)
        depth = offset @ forward
        x = offset @ right * camera.frustum_near / depth
        y = offset @ up * camera.frustum_near / depth
        # The frustum is as wide as the image's aspect ratio makes it.
        half_width = (camera.frustum_top - camera.frustum_bottom) / 2 * self.width / self.height
        column = (x - (camera.frustum_center - half_width)) / (2 * half_width) * self.width
        row = (camera.frustum_top - y) / (camera.frustum_top - camera.frustum_bottom) * self.height
        return float(column), float(row)

    def close(self) -> None:
        self.renderer.close()


PLANAR_DOT_RADIUS = 0.1
"""Radius of the dots of planar goals (x, y), as the mazes' with cells a metre wide."""


def _in_space(point: np.ndarray, height: float = PLANAR_DOT_RADIUS) -> np.ndarray:
    """A goal's position as a point in space: its first three entries, or for a planar goal
    (x, y) that point ``height`` above the floor."""
    point = np.asarray(point, dtype=np.float64)
    if len(point) >= 3:
        return point[:3]
    return np.concatenate([point, np.zeros(2 - len(point)), [height]])


def goal_markers(env: gym.Env, spec: EnvSpec, goal: np.ndarray, subgoal: np.ndarray | None) -> list[Marker]:
    """Markers for the task's goal and the current sub-goal (None: no sub-goal to show).

    Position goals get a red and a green dot. Goals with a rotation (the Hand tasks) are shown
    by the environment itself as a ghost block; the sub-goal gets a green ghost block of its
    own beside it.
    """
    if spec.quaternion is None:
        planar = len(goal) < 3
        radius, colour = (PLANAR_DOT_RADIUS, PLANAR_SUBGOAL_RGBA) if planar else (DOT_RADIUS, SUBGOAL_RGBA)
        markers = [Marker(_in_space(goal), GOAL_RGBA, radius)]
        if subgoal is not None:
            # Above the goal's dot and the mazes' ball, so that from above it shows where they meet.
            markers.append(Marker(_in_space(subgoal, 4 * PLANAR_DOT_RADIUS), colour, radius * 0.8))
        return markers
    if subgoal is None:
        return []
    start, stop = spec.quaternion
    position = np.array(subgoal[:3], dtype=np.float64)
    if getattr(env.unwrapped, "target_position", None) == "ignore":
        position = np.array(goal[:3], dtype=np.float64) + np.array([0.15, 0.0, 0.0]) + GHOST_BESIDE
    quaternion = np.asarray(subgoal[start:stop], dtype=np.float64)
    quaternion = quaternion / max(np.linalg.norm(quaternion), 1e-8)
    return [Marker(position, GHOST_SUBGOAL_RGBA, GHOST_HALF_SIZE, quaternion)]


@dataclasses.dataclass
class RenderedEpisode:
    """One deterministic episode: its frames (the state at t = 0..T), its record, and the
    frames worth a look, with captions."""

    frames: list[np.ndarray]
    episode: Episodes
    key_frames: list[tuple[int, str]]
    goal_pixels: list[tuple[float, float]]
    """Where the goal's marker landed in each frame (position goals; else empty)."""
    subgoal_pixels: list[tuple[float, float] | None]
    """Where the sub-goal's marker landed in each frame (None where none is shown)."""


def render_episode(
    env: gym.Env,
    agent: Agent,
    spec: EnvSpec,
    renderer: SceneRenderer,
    rng: np.random.Generator,
    bounds: np.ndarray | None,
    plan_of: Callable[[Episodes], list[dict[str, Any]]] | None = None,
) -> RenderedEpisode:
    """Play one deterministic episode, rendering each state with the goal and (``bounds``
    given: a dtd agent with those segment bounds) the sub-goal in force; ``plan_of`` (the
    agent's ``plan``) gives the key frames' captions their figures."""
    frames: list[np.ndarray] = []
    goal_pixels: list[tuple[float, float]] = []
    subgoal_pixels: list[tuple[float, float] | None] = []

    def on_step(t: int, goals: np.ndarray) -> None:
        goal = np.array(env.unwrapped.goal, dtype=np.float64)  # the task's goal, set at reset
        subgoal = goals[0] if bounds is not None else None
        markers = goal_markers(env, spec, goal, subgoal)
        frames.append(renderer.render(markers))
        if spec.quaternion is None:
            goal_pixels.append(renderer.project(markers[0].position))
        subgoal_pixels.append(renderer.project(markers[-1].position) if subgoal is not None else None)

    episode = run_episodes([env], agent, spec, False, rng, on_step=on_step)
    plan = plan_of(episode)[0] if plan_of is not None else None
    keys = key_frames(int(episode.length[0]), bounds, bool(episode.success[0]), plan)
    return RenderedEpisode(frames, episode, keys, goal_pixels, subgoal_pixels)


def key_frames(
    horizon: int, bounds: np.ndarray | None, success: bool, plan: dict[str, Any] | None = None
) -> list[tuple[int, str]]:
    """(frame, caption) pairs: the start, each segment's end (when the next sub-goal is set)
    and the final state, after ``horizon`` steps (the episode's length: a task may end it
    before the time limit, and segments it never began have no frame); without segments, the
    start, the middle and the end. With a ``plan``
    that has ``angles`` (goals with a rotation), the captions give them in degrees: the first
    sub-goal's turn from the start and the goal's, how far each segment ended from its
    sub-goal (reached or missed), and how far the episode ended from the goal."""
    final = f"final ({'success' if success else 'failure'})"
    if bounds is None:
        return [(0, "start"), (horizon // 2, f"t = {horizon // 2}"), (horizon, final)]
    angles = (plan or {}).get("angles")
    reached = (plan or {}).get("reached") or []
    start = "start: sub-goal 1 set"
    if angles:
        start += (
            f"\n{angles['start_to_subgoal'][0]:.0f}\N{DEGREE SIGN} from here; "
            f"goal {angles['start_to_goal']:.0f}\N{DEGREE SIGN} away"
        )
    frames = [(0, start)]
    for number, end in enumerate(bounds[1:-1], start=1):
        if end >= horizon:
            break
        last = number + 1 == len(bounds) - 1
        following = "the goal is pursued" if last else f"sub-goal {number + 1} set"
        caption = f"segment {number} ends: {following}"
        if angles:
            verdict = "reached" if number <= len(reached) and reached[number - 1] else "missed"
            caption += (
                f"\nsub-goal {number} {verdict}, "
                f"{angles['segment_end_to_subgoal'][number - 1]:.0f}\N{DEGREE SIGN} off"
            )
        frames.append((int(end), caption))
    if angles:
        final += f"\n{angles['final_to_goal']:.0f}\N{DEGREE SIGN} from the goal"
    frames.append((horizon, final))
    return frames


def marker_legend(rotation: bool, subgoals: bool, planar: bool = False) -> str:
    """What the markers of a rendered episode stand for (``planar``: goals are points x, y)."""
    if rotation:
        legend = "the task's ghost block = goal"
        return legend + (", green block = current sub-goal" if subgoals else "")
    colour = "blue" if planar else "green"
    return "red = goal" + (f", {colour} = current sub-goal" if subgoals else "")


def is_planar(spec: EnvSpec) -> bool:
    """Whether the task's goals are points on a plane (x, y), as the mazes' are."""
    return spec.goal_dim == 2 and spec.quaternion is None


def write_video(frames: Sequence[np.ndarray], path: Path, fps: int = 25) -> Path:
    """Frames as an H.264 MP4 (yuv420p, which browsers play), read back once: ffmpeg's own
    failures (a full disk) leave a file that cannot be read, and are a :class:`MachineError`."""
    import errno

    import imageio.v2 as imageio
    import imageio_ffmpeg

    from dtd.errors import MachineError
    from dtd.training.atomic import machine_failure

    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimwrite(
        path, list(frames), fps=fps, codec="libx264", quality=7, macro_block_size=16, ffmpeg_log_level="quiet"
    )
    try:
        imageio_ffmpeg.count_frames_and_secs(str(path))
    except RuntimeError as exc:
        full = shutil.disk_usage(path.parent).free < 1 << 20
        reason = (
            OSError(errno.ENOSPC, "No space left on device") if full else OSError(errno.EIO, "ffmpeg failed")
        )
        raise MachineError(machine_failure(reason, path)) from exc
    return path


def write_strip(episode: RenderedEpisode, path: Path, title: str) -> Path:
    """The key frames side by side with their captions, as a PNG."""
    plt = pyplot()

    count = len(episode.key_frames)
    figure, axes = plt.subplots(1, count, figsize=(3.2 * count, 3.6), layout="constrained")
    for axis, (frame, caption) in zip(np.atleast_1d(axes), episode.key_frames, strict=True):
        axis.imshow(episode.frames[frame])
        axis.set_title(f"t = {frame}: {caption}", fontsize=9)
        axis.set_axis_off()
    figure.suptitle(title, fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=100)
    plt.close(figure)
    return path


@dataclasses.dataclass(frozen=True)
class RenderedFiles:
    """What :func:`render_run` wrote for one episode, and the episode's plan."""

    video: Path
    strip: Path
    plan: dict[str, Any]


def render_run(
    run_dir: Path,
    episodes: int,
    out: Path,
    checkpoint: str = "latest",
    seed: int = EVAL_SEED,
    width: int = 480,
    height: int = 480,
) -> list[RenderedFiles]:
    """Render ``episodes`` deterministic episodes of a trained run into ``out``: per episode an
    MP4 and a PNG strip of key frames, and ``plans.json`` with every episode's plan."""
    import json

    from dtd.errors import ConfigError
    from dtd.training.atomic import staged
    from dtd.training.trained_run import load_run

    if episodes < 1:
        raise ConfigError(f"--episodes must be at least 1, got {episodes}")
    if width < 16 or height < 16:
        raise ConfigError(f"--width and --height must be at least 16, got {width}x{height}")
    loaded = load_run(Path(run_dir), checkpoint, seed, envs=1)
    env, agent, spec = loaded.envs[0], loaded.agent, loaded.spec
    planner = agent.planner()
    bounds = planner.bounds if planner is not None else None
    plan_of = planner.plan if planner is not None else None
    written = []
    # Every file written at once, when every episode is: an interrupt or a full disk leaves none.
    with contextlib.ExitStack() as stack:
        stack.callback(loaded.close)
        folder = stack.enter_context(staged(Path(out), "rendered episodes"))
        renderer = SceneRenderer(env, width, height, camera_for(spec.env_id))
        stack.callback(renderer.close)
        for number in range(1, episodes + 1):
            rendered = render_episode(env, agent, spec, renderer, loaded.rng, bounds, plan_of)
            name = f"episode-{number}"
            title = (
                f"{loaded.config.algo.value} on {spec.env_id}, epoch {loaded.checkpoint.epoch}, "
                f"episode {number}: "
                f"{marker_legend(spec.quaternion is not None, bounds is not None, is_planar(spec))}"
            )
            write_video(rendered.frames, folder / f"{name}.mp4")
            write_strip(rendered, folder / f"{name}-keyframes.png", title)
            plan = plan_of(rendered.episode)[0] if plan_of else episode_plan(rendered.episode, 0, None)
            written.append(
                RenderedFiles(Path(out) / f"{name}.mp4", Path(out) / f"{name}-keyframes.png", plan)
            )
        plans = [{"episode": n, **files.plan} for n, files in enumerate(written, start=1)]
        (folder / "plans.json").write_text(json.dumps(plans, indent=1) + "\n")
    return written
