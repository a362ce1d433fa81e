"""``dtd export``: a trained run's acting paths as ONNX models, with ``policy.json`` (what a
program needs to drive them: dimensions, when to ask for the next sub-goal, the goal box,
versions) and a ``README.md`` with an example that runs them with ONNX Runtime alone.

Models are traced with PyTorch's TorchScript-based ONNX exporter, which needs no package
beyond torch and traces these small perceptrons in well under a second; every model is then
run with ONNX Runtime on random inputs and compared with the torch agent before it is kept.
"""

from __future__ import annotations

import dataclasses
import io
import json
import warnings
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from dtd.agents.interface import Agent
from dtd.envs.make import env_kwargs
from dtd.envs.spec import EnvSpec
from dtd.errors import ConfigError, DtdError
from dtd.export.paths import PolicyPath, SubgoalPath, SubgoalValuePath
from dtd.training.atomic import staged
from dtd.training.run_dir import package_versions
from dtd.training.trained_run import LoadedRun, load_run

OPSET = 17
"""ONNX opset of the exported models (ONNX Runtime 1.14 and newer run it)."""
TOLERANCE = 1e-5
"""The most an exported model's output may differ from the torch agent's."""
FORMAT = "dtd-onnx-policy/1"


@dataclasses.dataclass(frozen=True)
class ModelFile:
    """One exported model: its role, file, named inputs and output with their widths."""

    role: str
    file: str
    inputs: dict[str, int]
    output: tuple[str, int]
    module: nn.Module = dataclasses.field(repr=False, compare=False)


@dataclasses.dataclass(frozen=True)
class Exported:
    """What :func:`export_run` wrote."""

    out: Path
    files: list[Path]
    policy: dict[str, Any]
    largest_difference: float
    """The largest difference between ONNX Runtime's outputs and the torch agent's, over the
    random inputs each model was checked on."""


def require_onnx() -> None:
    """A :class:`DtdError` saying how to install what export needs, when it is missing."""
    for name in ("onnx", "onnxruntime"):
        try:
            __import__(name)
        except ImportError as exc:
            raise DtdError(
                f"dtd export needs {name}, which is not installed: pip install 'dtd[export]'"
            ) from exc


def models_of(agent: Agent, spec: EnvSpec) -> list[ModelFile]:
    """The models an agent's acting is made of: its policy, and for an agent that sets itself
    sub-goals, the high level's sub-goal and value paths with the policy pursuing them."""
    obs, goal = spec.obs_dim, spec.goal_dim
    policy = PolicyPath(agent.motor_learner())
    planner = agent.planner()
    if planner is None:
        return [
            ModelFile(
                "policy",
                "policy.onnx",
                {"observation": obs, "goal": goal},
                ("action", spec.action_dim),
                policy,
            )
        ]
    return [
        ModelFile(
            "low_level", "low_level.onnx", {"observation": obs, "subgoal": goal},
            ("action", spec.action_dim), policy,
        ),
        ModelFile(
            "high_level", "high_level.onnx", {"observation": obs, "achieved_goal": goal, "goal": goal},
            ("subgoal", goal), SubgoalPath(planner.high),
        ),
        ModelFile(
            "high_level_value", "high_level_value.onnx",
            {"observation": obs, "achieved_goal": goal, "goal": goal, "subgoal": goal},
            ("value", 1), SubgoalValuePath(planner.high),
        ),
    ]  # fmt: skip


def onnx_bytes(model: ModelFile) -> bytes:
    """The model traced to ONNX, its batch dimension dynamic."""
    examples = tuple(torch.zeros(2, width) for width in model.inputs.values())
    names = [*model.inputs, model.output[0]]
    buffer = io.BytesIO()
    model.module.eval()
    with warnings.catch_warnings(), torch.no_grad():
        # The TorchScript-based exporter announces that torch.export's is now the default.
        warnings.simplefilter("ignore", category=FutureWarning)
        warnings.simplefilter("ignore", category=UserWarning)
        warnings.simplefilter("ignore", category=DeprecationWarning)
        torch.onnx.export(
            model.module,
            examples,
            buffer,
            input_names=list(model.inputs),
            output_names=[model.output[0]],
            dynamic_axes={name: {0: "batch"} for name in names},
            opset_version=OPSET,
            dynamo=False,
        )
    return buffer.getvalue()


def check_against_torch(model: ModelFile, data: bytes, rng: np.random.Generator, rows: int = 256) -> float:
    """The largest difference between ONNX Runtime's outputs and the module's on ``rows``
    random inputs (raw scale: a few units around zero)."""
    import onnxruntime

    session = onnxruntime.InferenceSession(data, providers=["CPUExecutionProvider"])
    feeds = {
        name: rng.normal(0.0, 2.0, (rows, width)).astype(np.float32) for name, width in model.inputs.items()
    }
    (answer,) = session.run([model.output[0]], feeds)
    with torch.no_grad():
        expected = model.module(*(torch.from_numpy(values) for values in feeds.values())).numpy()
    return float(np.max(np.abs(answer - expected)))


def export_run(run_dir: Path, out: Path, checkpoint: str = "latest", force: bool = False) -> Exported:
    """Write the ONNX models of a run's agent at ``checkpoint``, ``policy.json`` and a
    ``README.md`` into ``out`` (refused when ``out`` holds files, unless ``force``)."""
    require_onnx()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ConfigError(
            f"--out {out} is a file; the export writes a directory of files: give another --out"
        )
    if out.exists() and any(out.iterdir()) and not force:
        raise ConfigError(f"{out} already exists; give --force to replace what is in it, or another --out")
    with load_run(Path(run_dir), checkpoint) as loaded:
        agent, spec = loaded.agent, loaded.spec
        models = models_of(agent, spec)
        rng = np.random.default_rng(0)
        files, largest = {}, 0.0
        for model in models:
            data = onnx_bytes(model)
            difference = check_against_torch(model, data, rng)
            if not difference <= TOLERANCE:
                raise DtdError(
                    f"the exported {model.role} differs from the agent by {difference:.2e} (over {TOLERANCE})"
                )
            largest = max(largest, difference)
            files[model.file] = data
        policy = describe(loaded, agent, spec, models, largest)
    files["policy.json"] = (json.dumps(policy, indent=1) + "\n").encode()
    files["README.md"] = readme(policy).encode()
    # Every file or none: a full disk or an interrupt leaves --out as it was.
    with staged(out, "the exported models") as folder:
        for name, data in files.items():
            (folder / name).write_bytes(data)
    return Exported(out, [out / name for name in files], policy, largest)


def describe(
    loaded: LoadedRun,
    agent: Agent,
    spec: EnvSpec,
    models: list[ModelFile],
    largest: float,
) -> dict[str, Any]:
    """policy.json: everything a program needs to drive the models, and where they came from."""
    versions = package_versions()
    for name in ("onnx", "onnxruntime"):
        versions[name] = metadata.version(name)
    policy: dict[str, Any] = {
        "format": FORMAT,
        "env_id": spec.env_id,
        "env_kwargs": env_kwargs(loaded.config.env_kwargs),
        "algo": loaded.config.algo.value,
        "opset": OPSET,
        "models": {
            model.role: {
                "file": model.file,
                "inputs": {name: ["batch", width] for name, width in model.inputs.items()},
                "output": {
                    model.output[0]: ["batch"] if model.output[1] == 1 else ["batch", model.output[1]]
                },
                "dtype": "float32",
            }
            for model in models
        },
        "obs_dim": spec.obs_dim,
        "time_feature": loaded.config.time_feature,
        "goal_dim": spec.goal_dim,
        "action_dim": spec.action_dim,
        "action_max": spec.action_max,
        "horizon": spec.horizon,
        "ends_on_goal": spec.ends_on_goal,
        "goal_box": {"low": list(spec.goal_low), "high": list(spec.goal_high)},
        "goal_quaternion": list(spec.quaternion) if spec.quaternion else None,
        "checkpoint": {
            "run": loaded.run.root.name,
            "path": loaded.run.named(loaded.path),
            "epoch": loaded.checkpoint.epoch,
            "env_steps": loaded.checkpoint.env_steps,
        },
        "largest_difference_from_torch": largest,
        "versions": versions,
    }
    planner = agent.planner()
    if planner is not None:
        bounds = [int(bound) for bound in planner.bounds]
        policy["segments"] = {
            "bounds": bounds,
            "rule": (
                "at each step t in bounds[:-1] a segment starts: ask high_level for a sub-goal, "
                "except in the last segment (t == bounds[-2]), which pursues the goal itself; "
                "between those steps keep the sub-goal; low_level acts on it at every step"
            ),
        }
    return policy


def readme(policy: dict[str, Any]) -> str:
    """DIR/README.md: what the files are and an example with ONNX Runtime."""
    dtd = "segments" in policy
    files = "\n".join(
        f"- `{model['file']}`: ({', '.join(model['inputs'])}) -> {next(iter(model['output']))}"
        for model in policy["models"].values()
    )
    if dtd:
        acting = """bounds = policy["segments"]["bounds"]
for t in range(policy["horizon"]):
    if t in bounds[:-1]:  # a segment starts: the next sub-goal (the goal itself in the last one)
        inputs = {"observation": o["observation"][None], "achieved_goal": o["achieved_goal"][None],
                  "goal": o["desired_goal"][None]}
        goal = inputs["goal"] if t == bounds[-2] else high.run(None, cast(inputs))[0]
    action = low.run(None, cast({"observation": o["observation"][None], "subgoal": goal}))[0]
    o, reward, terminated, truncated, info = env.step(action[0])
    if terminated or truncated: break  # the time limit, or the goal reached where that ends it"""
        sessions = (
            "low, high = (ort.InferenceSession(policy['models'][k]['file']) "
            "for k in ('low_level', 'high_level'))"
        )
    else:
        acting = """for t in range(policy["horizon"]):
    inputs = {"observation": o["observation"][None], "goal": o["desired_goal"][None]}
    action = actor.run(None, cast(inputs))[0]
    o, reward, terminated, truncated, info = env.step(action[0])
    if terminated or truncated: break  # the time limit, or the goal reached where that ends it"""
        sessions = 'actor = ort.InferenceSession(policy["models"]["policy"]["file"])'
    if policy.get("time_feature"):  # the models' observation ends with the fraction of the episode left
        observed = 'np.append(o["observation"], 1 - t / policy["horizon"])[None]'
        acting = acting.replace('o["observation"][None]', observed)
    example = f"""import json, gymnasium as gym, gymnasium_robotics, numpy as np, onnxruntime as ort
gym.register_envs(gymnasium_robotics)
policy = json.load(open("policy.json"))
{sessions}
cast = lambda feeds: {{name: np.asarray(value, dtype=np.float32) for name, value in feeds.items()}}
env = gym.make(policy["env_id"], **policy["env_kwargs"])
o, _ = env.reset(seed=0)
{acting}
success = float(info.get("is_success", info.get("success", 0.0)))  # the mazes say "success"
print(json.dumps({{"success": success, "steps": t + 1, "achieved_goal": o["achieved_goal"].tolist()}}))"""
    checkpoint = policy["checkpoint"]
    when = "when to ask for the next sub-goal (`segments`), " if dtd else ""
    return f"""# {policy["algo"]} on {policy["env_id"]}, exported

From `{checkpoint["path"]}` of the run `{checkpoint["run"]}` (epoch {checkpoint["epoch"]},
{checkpoint["env_steps"]:,} env steps), by `dtd export`. ONNX opset {policy["opset"]}; every
input and output is float32 with a batch dimension of any size. Inputs are the environment's
raw values: clipping, normalisation and the scaling of actions (and of sub-goals into the goal
box) are inside the models. On random inputs the models' outputs differed from the torch
agent's by at most
{policy["largest_difference_from_torch"]:.1e}.

{files}
- `policy.json`: the task and its constructor's arguments (`env_kwargs`), dimensions (with
  `time_feature`, the observation the models take ends with 1 - t/T, the fraction of the
  episode left), the goal box, {when}the checkpoint, versions.

One episode with ONNX Runtime alone (run it in this folder; needs `gymnasium-robotics` and
`onnxruntime`):

```python
{example}
```
"""
