"""Replay memory per stored transition: the bytes the episode buffer holds for each step of
experience it keeps, for a task's dimensions and horizon and the mean length of its episodes.

The buffer keeps whole episodes in slots of the horizon T (padding past an episode's end), so a
task whose episodes end on reaching the goal, after L steps on average, pays T / L times the
bytes of a step for each step it keeps.

    python benchmarks/replay_memory.py --env FetchPush-v4
    python benchmarks/replay_memory.py --env PointMaze_UMaze-v3 --env-kwargs continuing_task=False \\
        --mean-length 120
"""

from __future__ import annotations

import argparse

from dtd.agents.buffer import EpisodeBuffer
from dtd.envs.make import env_kwargs, make_envs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True)
    parser.add_argument("--env-kwargs", nargs="*", default=[])
    parser.add_argument("--mean-length", type=float, default=None, help="steps per episode (default: T)")
    parser.add_argument("--episodes", type=int, default=1000, help="slots of the buffer measured")
    args = parser.parse_args()
    envs, spec = make_envs(args.env, 1, env_kwargs(args.env_kwargs))
    envs[0].close()
    buffer = EpisodeBuffer(args.episodes, spec.horizon, spec.obs_dim, spec.goal_dim, spec.action_dim)
    per_slot_step = buffer.nbytes / (args.episodes * spec.horizon)
    length_bytes = args.episodes * 8  # one int64 length per episode
    mean_length = args.mean_length or spec.horizon
    dims = f"obs {spec.obs_dim}, goal {spec.goal_dim}, action {spec.action_dim}, horizon {spec.horizon}"
    print(f"{spec.env_id}: {dims}")
    print(
        f"bytes per step of a slot: {per_slot_step:.2f} (of which the episode's length: "
        f"{length_bytes / (args.episodes * spec.horizon):.3f})"
    )
    print(
        f"bytes per stored transition at a mean episode length of {mean_length:g}: "
        f"{per_slot_step * spec.horizon / mean_length:.2f}"
    )


if __name__ == "__main__":
    main()
