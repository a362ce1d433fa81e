"""Peer benchmark: Stable-Baselines3's DDPG + HerReplayBuffer against dtd's ``her``, with
the same hyperparameters, task, seed and machine, one after the other in one run.

Both evaluate 10 deterministic episodes every 5,000 env steps (success = ``is_success`` at
the last step); wall time includes evaluation. Differences the libraries do not let us
remove: SB3 moves its targets after every update (dtd by 0.05 once per 40, as baselines'
HER), so SB3 gets the per-update rate that moves them as far over 40 updates,
1 - 0.95 ** (1 / 40); and it takes no random actions. SB3 normalises inputs with its ``VecNormalize`` wrapper.
Needs ``pip install -e .[bench]``.

    python benchmarks/peer_sb3.py --env FetchPush-v4 --steps 300000 --run-dir runs/peer
"""

from __future__ import annotations

import argparse
import csv
import platform
import time
from pathlib import Path

import numpy as np
import torch

from dtd.config import Algo, TrainConfig
from dtd.envs.make import make_env
from dtd.training.lifecycle import train_for_steps
from dtd.training.run_dir import RunDir, read_config

Curve = list[tuple[int, float, float]]  # (env steps, eval success, wall seconds)


def sb3_curve(
    env_id: str, steps: int, seed: int, eval_every: int, test_episodes: int, tau: float | None = None
) -> Curve:
    """Train SB3's DDPG + HER and evaluate it along the way; ``tau`` per update (None: the
    rate that moves the targets as far over 40 updates as dtd's 0.05 once per 40)."""
    from stable_baselines3 import DDPG, HerReplayBuffer
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.noise import NormalActionNoise
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    # Running mean/std normalisation of observations and goals (clip 5), as in dtd; the HER
    # buffer keeps raw goals and normalises what it samples.
    env = VecNormalize(
        DummyVecEnv([lambda: make_env(env_id)]), norm_obs=True, norm_reward=False, clip_obs=5.0, gamma=0.98
    )
    eval_env = make_env(env_id)
    eval_env.reset(seed=seed + 10_000)
    curve: Curve = []
    start = time.perf_counter()

    class Evaluate(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % eval_every == 0:
                successes = []
                for _ in range(test_episodes):
                    obs, _ = eval_env.reset()
                    done = False
                    while not done:
                        action, _ = self.model.predict(env.normalize_obs(obs), deterministic=True)
                        obs, _, terminated, truncated, info = eval_env.step(action)
                        done = terminated or truncated
                    successes.append(float(info["is_success"]))
                curve.append((self.num_timesteps, float(np.mean(successes)), time.perf_counter() - start))
                print(f"sb3  {self.num_timesteps:>8} steps  eval success {curve[-1][1]:.2f}  "
                      f"wall {curve[-1][2]:.0f}s", flush=True)  # fmt: skip
            return True

    action_dim = env.action_space.shape[0]
    model = DDPG(
        "MultiInputPolicy",
        env,
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        learning_rate=1e-3,
        buffer_size=1_000_000,
        batch_size=256,
        tau=1.0 - 0.95 ** (1.0 / 40) if tau is None else tau,
        gamma=0.98,
        train_freq=(2, "episode"),
        gradient_steps=40,
        action_noise=NormalActionNoise(np.zeros(action_dim), 0.2 * np.ones(action_dim)),
        policy_kwargs={"net_arch": [256, 256, 256]},
        seed=seed,
        device="cpu",
    )
    model.learn(total_timesteps=steps, callback=Evaluate())
    return curve


def dtd_curve(env_id: str, steps: int, seed: int, run_dir: Path) -> Curve:
    """Train dtd's ``her`` (resuming a run left in ``run_dir``) and read its curve."""
    train_for_steps(TrainConfig(env=env_id, algo=Algo.her, seed=seed), steps, run_dir)
    run = RunDir(run_dir)
    with open(run.metrics) as file:
        return [
            (int(r["env_steps"]), float(r["eval_success"]), float(r["wall_s"])) for r in csv.DictReader(file)
        ]


def first_reaching(curve: Curve, threshold: float) -> str:
    for steps, success, wall in curve:
        if success >= threshold:
            return f"{steps:>8} steps {wall:>7.0f}s"
    return f"{'not reached':>22}"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--env", default="FetchPush-v4")
    parser.add_argument("--steps", type=int, default=300_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--run-dir", type=Path, required=True, help="where dtd's run goes")
    parser.add_argument("--skip-sb3", action="store_true", help="only dtd (e.g. SB3 measured before)")
    parser.add_argument(
        "--sb3-tau",
        type=float,
        default=None,
        help="SB3's target rate per update (default: as far over 40 updates as dtd's 0.05 once per 40)",
    )
    args = parser.parse_args()
    # Each library with the torch threads it would use on this machine by default.
    default_threads = torch.get_num_threads()
    curves = {"dtd her": dtd_curve(args.env, args.steps, args.seed, args.run_dir)}
    if not args.skip_sb3:
        torch.set_num_threads(default_threads)
        curves["sb3 ddpg+her"] = sb3_curve(
            args.env, args.steps, args.seed, eval_every=5000, test_episodes=10, tau=args.sb3_tau
        )
    dtd_threads = read_config(RunDir(args.run_dir)).threads
    print(f"# {args.env}, seed {args.seed}, {args.steps} env steps, {platform.machine()}, "
          f"torch threads: dtd {dtd_threads}, sb3 {default_threads}")  # fmt: skip
    header = f"{'library':<14} {'to 0.5 success':>22} {'to 0.9 success':>22}"
    print(f"{header} {'final':>6} {'wall':>7} {'steps/s':>8}")
    for name, curve in curves.items():
        steps, success, wall = curve[-1]
        print(f"{name:<14} {first_reaching(curve, 0.5)} {first_reaching(curve, 0.9)} {success:>6.2f} "
              f"{wall:>6.0f}s {steps / wall:>8.0f}")  # fmt: skip


if __name__ == "__main__":
    main()
