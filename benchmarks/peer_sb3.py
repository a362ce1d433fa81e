"""Peer benchmark: Stable-Baselines3 against dtd's ``her`` with the same hyperparameters,
task, seed and machine, one after the other in one run.

``--peer ddpg``: SB3's DDPG + HerReplayBuffer against dtd's ``her`` at its defaults. SB3 moves
its targets after every update (dtd by 0.05 once per 40, as baselines' HER), so SB3 gets the
per-update rate that moves them as far over 40 updates, 1 - 0.95 ** (1 / 40); and it takes no
random actions.

``--peer tqc``: sb3-contrib's TQC + HerReplayBuffer against dtd's ``her --learner tqc`` at
RL Zoo's recipe for the Fetch tasks, scaled to 3x256 networks and batch 256: one update per env
step, gamma 0.95, tau 0.05, k = 4, 2 critics of 25 quantiles with 2 dropped each, the entropy
temperature tuned from 1.0 toward -dim(A), learning rate 1e-3, no action penalty, no random
actions, no return clip (dtd's settings made so). dtd moves its targets once per cycle of 100
updates, by the share SB3's 100 steps of 0.05 move them, 1 - 0.95 ** 100; SB3 learns from its
100th step, dtd after its first cycle (100 steps).

Both evaluate 10 deterministic episodes every 5,000 env steps (success = ``is_success`` at the
last step); wall time includes evaluation. SB3 normalises inputs with its ``VecNormalize``
wrapper (clip 5, as dtd). Needs ``pip install -e .[bench]``.

    python benchmarks/peer_sb3.py --env FetchPush-v4 --steps 300000 --run-dir runs/peer
    python benchmarks/peer_sb3.py --peer tqc --steps 100000 --seed 0 --run-dir runs/peer-tqc-0
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dtd.config import Algo, LearnerKind, Precision, TrainConfig
from dtd.envs.make import make_env
from dtd.training.lifecycle import train_for_steps
from dtd.training.run_dir import RunDir, read_config

Curve = list[tuple[int, float, float]]  # (env steps, eval success, wall seconds)


TQC_GAMMA = 0.95
TQC_TAU = 0.05
TQC_UPDATES_PER_CYCLE = 100  # one per env step of a cycle's 2 episodes of 50


def tqc_config(env_id: str, seed: int) -> TrainConfig:
    """dtd's ``her --learner tqc`` at the settings of SB3's TQC + HER below."""
    config = TrainConfig(env=env_id, algo=Algo.her, seed=seed, random_eps=0.0, n_step=1)
    learner = dataclasses.replace(
        config.learner,
        learner=LearnerKind.tqc,
        hidden_sizes=(256, 256, 256),
        batch_size=256,
        gamma=TQC_GAMMA,
        polyak=(1.0 - TQC_TAU) ** TQC_UPDATES_PER_CYCLE,
        action_l2=0.0,
        clip_return=False,
        initial_temperature=1.0,
    )
    return dataclasses.replace(config, learner=learner, updates_per_cycle=TQC_UPDATES_PER_CYCLE)


def sb3_curve(
    env_id: str,
    steps: int,
    seed: int,
    eval_every: int,
    test_episodes: int,
    tau: float | None = None,
    peer: str = "ddpg",
) -> Curve:
    """Train SB3's DDPG + HER (or TQC + HER) and evaluate it along the way; DDPG's ``tau`` per
    update (None: the rate that moves the targets as far over 40 updates as dtd's 0.05 once
    per 40)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    gamma = TQC_GAMMA if peer == "tqc" else 0.98
    # Running mean/std normalisation of observations and goals (clip 5), as in dtd; the HER
    # buffer keeps raw goals and normalises what it samples.
    env = VecNormalize(
        DummyVecEnv([lambda: make_env(env_id)]), norm_obs=True, norm_reward=False, clip_obs=5.0, gamma=gamma
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

    model = sb3_tqc(env, seed) if peer == "tqc" else sb3_ddpg(env, seed, tau)
    model.learn(total_timesteps=steps, callback=Evaluate())
    return curve


def sb3_tqc(env: Any, seed: int) -> Any:
    """sb3-contrib's TQC + HER at RL Zoo's recipe for the Fetch tasks, 3x256 and batch 256."""
    from sb3_contrib import TQC
    from stable_baselines3 import HerReplayBuffer

    return TQC(
        "MultiInputPolicy",
        env,
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        learning_rate=1e-3,
        buffer_size=1_000_000,
        batch_size=256,
        learning_starts=TQC_UPDATES_PER_CYCLE,
        tau=TQC_TAU,
        gamma=TQC_GAMMA,
        train_freq=1,
        gradient_steps=1,
        ent_coef="auto",
        top_quantiles_to_drop_per_net=2,
        policy_kwargs={"net_arch": [256, 256, 256], "n_critics": 2, "n_quantiles": 25},
        seed=seed,
        device="cpu",
    )


def sb3_ddpg(env: Any, seed: int, tau: float | None) -> Any:
    """SB3's DDPG + HER at dtd's ``her`` defaults."""
    from stable_baselines3 import DDPG, HerReplayBuffer
    from stable_baselines3.common.noise import NormalActionNoise

    action_dim = env.action_space.shape[0]
    return DDPG(
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


def dtd_curve(config: TrainConfig, steps: int, run_dir: Path) -> Curve:
    """Train dtd's run of ``config`` (resuming a run left in ``run_dir``) and read its curve."""
    train_for_steps(config, steps, run_dir)
    run = RunDir(run_dir)
    with open(run.metrics) as file:
        return [
            (int(r["env_steps"]), float(r["eval_success"]), float(r["wall_s"])) for r in csv.DictReader(file)
        ]


def write_curve(path: Path, curve: Curve) -> None:
    """The curve as a CSV of env_steps, eval_success and wall_s (as dtd's metrics.csv names them)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["env_steps", "eval_success", "wall_s"])
        writer.writerows(curve)


def first_reaching(curve: Curve, threshold: float) -> str:
    for steps, success, wall in curve:
        if success >= threshold:
            return f"{steps:>8} steps {wall:>7.0f}s"
    return f"{'not reached':>22}"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--peer", choices=["ddpg", "tqc"], default="ddpg", help="SB3's algorithm")
    parser.add_argument("--env", default="FetchPush-v4")
    parser.add_argument("--steps", type=int, default=300_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--run-dir", type=Path, required=True, help="where dtd's run goes")
    parser.add_argument("--skip-sb3", action="store_true", help="only dtd (e.g. SB3 measured before)")
    parser.add_argument("--sb3-threads", type=int, default=0, help="SB3's torch threads (0: torch's default)")
    parser.add_argument("--skip-dtd", action="store_true", help="only SB3 (e.g. dtd measured before)")
    parser.add_argument("--precision", choices=["auto", "float32", "bfloat16"], default="auto", help="dtd's")
    parser.add_argument(
        "--sb3-tau",
        type=float,
        default=None,
        help="SB3's target rate per update (default: as far over 40 updates as dtd's 0.05 once per 40)",
    )
    args = parser.parse_args()
    # SB3 with the torch threads it would use on this machine by default, or as many as given
    # (dtd's default is one: two threads beside other busy processes wait for each other).
    sb3_threads = args.sb3_threads or torch.get_num_threads()
    config = (
        tqc_config(args.env, args.seed) if args.peer == "tqc" else TrainConfig(env=args.env, algo=Algo.her)
    )
    config = dataclasses.replace(config, seed=args.seed, precision=Precision(args.precision))
    curves = {}
    if not args.skip_dtd:
        curves[f"dtd her {config.learner.learner.value}"] = dtd_curve(config, args.steps, args.run_dir)
    if not args.skip_sb3:
        torch.set_num_threads(sb3_threads)
        curves[f"sb3 {args.peer}+her"] = sb3_curve(
            args.env, args.steps, args.seed, 5000, 10, tau=args.sb3_tau, peer=args.peer
        )
        write_curve(args.run_dir.with_name(args.run_dir.name + "-sb3.csv"), curves[f"sb3 {args.peer}+her"])
    dtd_threads = read_config(RunDir(args.run_dir)).threads if not args.skip_dtd else "-"
    shown_sb3_threads = "-" if args.skip_sb3 else sb3_threads
    print(f"# {args.env}, seed {args.seed}, {args.steps} env steps, {platform.machine()}, "
          f"torch threads: dtd {dtd_threads}, sb3 {shown_sb3_threads}")  # fmt: skip
    header = f"{'library':<14} {'to 0.5 success':>22} {'to 0.9 success':>22}"
    print(f"{header} {'final':>6} {'wall':>7} {'steps/s':>8}")
    for name, curve in curves.items():
        steps, success, wall = curve[-1]
        print(f"{name:<14} {first_reaching(curve, 0.5)} {first_reaching(curve, 0.9)} {success:>6.2f} "
              f"{wall:>6.0f}s {steps / wall:>8.0f}")  # fmt: skip


if __name__ == "__main__":
    main()
