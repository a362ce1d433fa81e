"""One self-contained HTML page per run: its configuration, training curves, the high level's
heatmaps (dtd), key-frame strips and videos of rendered episodes, and each episode's plan.

The page opens from disk with no server: ``RUN/report.html``, with its images and videos in
``RUN/report/`` beside it, referenced by relative paths.
"""

from __future__ import annotations

import dataclasses
import html
import json
from pathlib import Path
from typing import Any

from dtd.config import EVAL_SEED, flat_items
from dtd.experiments.curves import Curve, read_curve
from dtd.experiments.run_curves import RunCurve, final_success
from dtd.training.atomic import staged, write_text_atomic
from dtd.training.run_dir import RunDir, read_config

ASSETS = "report"
"""Folder beside report.html that holds its images and videos."""

# Marks each image and video as loaded or broken (data-status), and says so on the page.
_MEDIA_CHECK = """
<script>
function mark(element, ok) {
  element.dataset.status = ok ? "loaded" : "error";
  if (!ok) {
    const note = document.createElement("p");
    note.className = "broken";
    note.textContent = "could not load " + (element.currentSrc || element.src);
    element.after(note);
  }
}
for (const image of document.querySelectorAll("img")) {
  if (image.complete) mark(image, image.naturalWidth > 0);
  else {
    image.addEventListener("load", () => mark(image, image.naturalWidth > 0));
    image.addEventListener("error", () => mark(image, false));
  }
}
for (const video of document.querySelectorAll("video")) {
  if (video.readyState >= 1) mark(video, video.videoWidth > 0);
  else {
    video.addEventListener("loadedmetadata", () => mark(video, video.videoWidth > 0));
    video.addEventListener("error", () => mark(video, false));
  }
}
</script>
"""

_STYLE = """
<style>
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }
h1 { font-size: 1.5em; } h2 { margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.9em; }
td, th { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
img, video { max-width: 100%; }
.settings { columns: 2; } .settings table { width: 100%; }
.broken { color: #b00; font-weight: bold; }
.success { color: #070; } .failure { color: #b00; }
</style>
"""


@dataclasses.dataclass(frozen=True)
class Report:
    """What :func:`write_report` wrote."""

    page: Path
    assets: list[Path]


def write_report(
    run_dir: Path, episodes: int = 3, checkpoint: str = "latest", seed: int = EVAL_SEED, resolution: int = 60
) -> Report:
    """Render ``episodes`` episodes, draw the curves (and, for dtd on a Fetch block task, the
    heatmaps after the first epoch and at ``checkpoint``) and write ``RUN/report.html``."""
    from dtd.experiments.plots import draw
    from dtd.explain.render import marker_legend, render_run

    run = RunDir(Path(run_dir))
    config = read_config(run)
    curve = read_curve(run.root)
    sections = [_header(run, config, curve), _settings(config)]
    spec = json.loads(run.config.read_text()).get("derived", {}).get("spec", {})
    written: list[Path] = []
    # The files beside the page are written as a whole, before the page: a report that fails
    # (a checkpoint that cannot be read, a full disk, Ctrl-C) leaves the one before it.
    with staged(run.root / ASSETS, "the report") as assets_dir:
        if len(curve):
            figures = draw(config.env or "", {config.algo.value: [curve]}, assets_dir / "curves")
            written += figures
            picture = _image(figures[0], assets_dir, "eval success against epochs and env steps")
            sections.append(_section("Training", picture))

        if config.algo.sets_subgoals and spec.get("quaternion"):
            sections.append(_section("The high level's values", _NO_MAP_FOR_ROTATIONS))
        elif config.algo.sets_subgoals:
            sections.append(_heatmap_section(run, assets_dir, checkpoint, resolution, written))

        rendered = render_run(run.root, episodes, assets_dir / "episodes", checkpoint, seed)
        parts = []
        for number, files in enumerate(rendered, start=1):
            written += [files.video, files.strip]
            parts.append(
                f"<h3>Episode {number}: {_outcome(files.plan['success'])}</h3>"
                + _image(files.strip, assets_dir, f"key frames of episode {number}")
                + f'<video controls preload="metadata" src="{_relative(files.video, assets_dir)}"></video>'
            )
    assets = [run.root / ASSETS / path.relative_to(assets_dir) for path in written]
    planar = spec.get("goal_dim") == 2 and not spec.get("quaternion")
    legend = marker_legend(bool(spec.get("quaternion")), config.algo.sets_subgoals, planar).capitalize() + "."
    sections.append(_section("Episodes", f"<p>{legend}</p>" + "".join(parts)))
    sections.append(_section("Plans", _plans_table([files.plan for files in rendered])))
    sections.append(_section("Questioning the run", _explore_note(run, config, bool(spec.get("quaternion")))))

    title = f"{config.algo.value} on {config.env}: {run.root.name}"
    page = run.root / "report.html"
    body = "\n".join(sections)
    write_text_atomic(
        page,
        f"<!doctype html>\n<html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"{_STYLE}</head>\n<body>\n{body}\n{_MEDIA_CHECK}</body></html>\n",
    )
    return Report(page, assets)


def _final_text(run: RunDir, config: Any, curve: Curve) -> str:
    """The run's final success and the evaluation it comes from."""
    if not len(curve):
        return "-"
    final = final_success(RunCurve(run.root, str(config.env), config.algo.value, curve, config.test_episodes))
    source = run.final_evaluation.name if final.saved else "the last epoch's evaluation"
    return f"{final.value:.2f} over {final.episodes} episodes ({source})"


def _header(run: RunDir, config: Any, curve: Curve) -> str:
    facts = {
        "run directory": str(run.root.resolve()),
        "task": config.env,
        "algorithm": config.algo.value,
        "preset": config.preset.value,
        "seed": config.seed,
        "epochs finished": len(curve),
        "env steps": int(curve.env_steps[-1]) if len(curve) else 0,
        "final eval success": _final_text(run, config, curve),
        "best eval success": f"{curve.eval_success.max():.2f}" if len(curve) else "-",
        "training time": f"{curve.wall_s[-1] / 60:.1f} min" if len(curve) else "-",
    }
    versions = json.loads(run.config.read_text()).get("versions", {})
    facts["versions"] = ", ".join(f"{name} {version}" for name, version in versions.items())
    rows = "".join(
        f"<tr><th>{html.escape(name)}</th><td>{html.escape(str(value))}</td></tr>"
        for name, value in facts.items()
    )
    return f"<h1>{html.escape(config.algo.value)} on {html.escape(str(config.env))}</h1><table>{rows}</table>"


def _settings(config: Any) -> str:
    rows = "".join(
        f"<tr><td>--{html.escape(name.replace('_', '-'))}</td><td>{html.escape(json.dumps(value))}</td></tr>"
        for name, value in flat_items(config).items()
    )
    return _section("Configuration", f"<div class='settings'><table>{rows}</table></div>")


_NO_MAP_FOR_ROTATIONS = (
    "<p>No heatmap: this task's goal is the block's orientation (a unit quaternion, beside a "
    "position the rotation-only variants ignore), and the high level's sub-goals are orientations "
    "too, so a map of its values over the table has nothing to show. What the high level asks for "
    "is in the plans below: each sub-goal's turn from the start, how far from it the segment "
    "ended, and its angle to the goal; the key frames show the sub-goal as a green ghost block "
    "beside the goal's.</p>"
)


def _explore_note(run: RunDir, config: Any, rotation: bool) -> str:
    """How to open this run in ``dtd explore``, and what it shows for this run."""
    command = html.escape(f"dtd explore {run.root}")
    if rotation:
        what = "play episodes of any epoch kept and read their plans"
    elif config.algo.sets_subgoals:
        what = (
            "drag the block and the goal and watch the high level's values and its chosen sub-goal "
            "follow them, after any epoch kept, and play episodes from any placement"
        )
    else:
        what = "play episodes of any epoch kept from any placement of the block and the goal"
    return (
        f"<p>This page is fixed. To ask the run your own questions ({what}), run "
        f"<code>{command}</code> and open the address it prints (a page served on this machine; "
        "it needs the <code>explore</code> extra: <code>pip install 'dtd[explore]'</code>).</p>"
    )


def _heatmap_section(
    run: RunDir, assets_dir: Path, checkpoint: str, resolution: int, assets: list[Path]
) -> str:
    from dtd.errors import EnvError
    from dtd.explain.heatmap import run_heatmaps

    checkpoints = ("first", checkpoint) if run.first.exists() and checkpoint != "first" else (checkpoint,)
    try:
        path, columns = run_heatmaps(
            run.root, assets_dir / "heatmaps.png", checkpoints, resolution=resolution
        )
    except EnvError as exc:
        return _section(
            "The high level's values", f"<p>No heatmap for this task: {html.escape(str(exc))}</p>"
        )
    assets.append(path)
    planar = bool(columns) and columns[0][1][0].z is None
    where = (
        "over the task's goal box, from its own start (black) and goal (red)"
        if planar
        else "over the table, with the block in one corner and the goal in the other"
    )
    text = (
        f"<p>The high level's critic Q1(o, g, sub-goal) for every sub-goal on a grid {where}; the "
        "cross marks the sub-goal the agent would choose."
        + (" Left: after the first epoch; right: at the checkpoint shown." if len(checkpoints) > 1 else "")
        + "</p>"
    )
    picture = _image(path, assets_dir, "heatmaps of the high level's values")
    return _section("The high level's values", text + picture)


def _plans_table(plans: list[dict[str, Any]]) -> str:
    def point(values: list[float]) -> str:
        return "(" + ", ".join(f"{v:.3f}" for v in values) + ")"

    head = "<tr><th>episode</th><th>start</th><th>sub-goals (where the segment ended)</th><th>goal</th>"
    head += "<th>final</th><th>outcome</th></tr>"
    rows = []
    for number, plan in enumerate(plans, start=1):
        angles = plan.get("angles")

        def turns(n: int, angles: dict[str, Any] | None = angles) -> str:
            if not angles:
                return ""
            return (
                f"; turned {angles['start_to_subgoal'][n]:.0f}&deg; from the start, "
                f"{angles['subgoal_to_goal'][n]:.0f}&deg; from the goal, "
                f"ended {angles['segment_end_to_subgoal'][n]:.0f}&deg; from it"
            )

        steps = "<br>".join(
            f"{n + 1}: {point(subgoal)} {'reached' if reached else 'missed'} ({point(end)}){turns(n)}"
            for n, (subgoal, end, reached) in enumerate(
                zip(plan["subgoals"], plan["segment_ends"], plan["reached"], strict=True)
            )
        )
        cells = [str(number), point(plan["start"]), steps or "-", point(plan["goal"]), point(plan["final"])]
        rows.append(
            "<tr>"
            + "".join(f"<td>{cell}</td>" for cell in cells)
            + f"<td>{_outcome(plan['success'])}</td></tr>"
        )
    return f"<table>{head}{''.join(rows)}</table>"


def _outcome(success: bool) -> str:
    return "<span class='success'>success</span>" if success else "<span class='failure'>failure</span>"


def _section(title: str, content: str) -> str:
    return f"<h2>{html.escape(title)}</h2>\n{content}"


def _image(path: Path, assets_dir: Path, alt: str) -> str:
    return f'<p><img src="{_relative(path, assets_dir)}" alt="{html.escape(alt)}"></p>'


def _relative(path: Path, assets_dir: Path) -> str:
    """The page's link to ``path``, written into ``assets_dir`` (while the files are staged)."""
    return html.escape(f"{ASSETS}/{Path(path).relative_to(assets_dir).as_posix()}")
