"""What the high level's critic says a segment is worth, against what the episodes earned.

Reads the replay buffer in a dtd run's latest checkpoint and, for the segment before the last
of its most recent ``--episodes`` episodes, compares three figures, each against the task's
goal and against goals relabelled to ones achieved later in the episode (high-level HER):

- ``Q1``: the critic at the sub-goal the episode pursued;
- ``bootstrap``: the target it is trained toward by default, the segment's reward plus
  gamma1 * Q1'(o', g, g), the target critic with the goal as the last segment's sub-goal;
- ``observed``: the segment's reward plus what the episode went on to earn against g (the
  last segment's mean reward, then the final reward held for ever), ``--high-target observed``.

Where the bootstrap sits far from what was observed for relabelled goals but not for the
task's own, the critic's values at (o', g', g'), an input region few stored transitions
train, are off. The episodes explored (noise, random actions, perturbation sub-goals), so
the observed returns are those of the exploring agent.

    python benchmarks/high_value_bias.py runs/push-dtd-0 --episodes 1000
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from dtd.agents.dot_to_dot import DotToDotAgent
from dtd.agents.segments import sample_segment_transitions
from dtd.training.trained_run import load_run


def figures(run_dir: Path, episodes: int, samples: int) -> dict[str, dict[str, float]]:
    with load_run(run_dir, "latest") as loaded:
        agent = loaded.agent
    if not isinstance(agent, DotToDotAgent) or agent.segments < 2:
        raise SystemExit(f"{run_dir}: needs a dtd run with two segments or more")
    agent.buffer.load_state_dict(loaded.checkpoint.agent["buffer"])
    stored = agent.buffer.stored()
    newest = agent.buffer.oldest_first()[-episodes:]
    recent = type(stored)(*(part[newest] for part in stored))
    high, gamma = agent.high, agent.high.gamma
    rng = np.random.default_rng(0)
    result = {}
    for name, relabel in (("task's goal", 0.0), ("relabelled goal", 1.0)):
        batch = sample_segment_transitions(
            recent, agent.bounds, samples, rng, relabel, 0.0, agent.goals.reward, gamma
        )
        rows = batch.next_value_given
        obs, goal, action = batch.obs[rows], batch.goal[rows], batch.action[rows]
        with torch.no_grad():
            q = high.q_values(obs, goal, action)
            next_inputs = high.inputs(torch.as_tensor(batch.next_obs[rows]), goal)
            goal_as_action = torch.as_tensor(goal, dtype=torch.float32)
            next_q = high._q(high.critic_target, next_inputs, goal_as_action).numpy().ravel()
        low, top = high.return_bounds
        bootstrap = np.clip(batch.reward[rows] + gamma * next_q, low, top)
        observed = np.clip(batch.reward[rows] + gamma * batch.next_value[rows], low, top)
        result[name] = {
            "Q1": float(np.mean(q)),
            "bootstrap": float(np.mean(bootstrap)),
            "observed": float(np.mean(observed)),
            "|bootstrap - observed|": float(np.mean(np.abs(bootstrap - observed))),
            "|Q1 - observed|": float(np.mean(np.abs(q - observed))),
        }
    return result


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--episodes", type=int, default=1000, help="the newest episodes of the replay")
    parser.add_argument("--samples", type=int, default=20000, help="transitions sampled per kind of goal")
    args = parser.parse_args()
    for run in args.runs:
        print(run)
        for name, values in figures(run, args.episodes, args.samples).items():
            print(f"  {name:16}" + "  ".join(f"{key} {value:.3f}" for key, value in values.items()))


if __name__ == "__main__":
    main()
