"""Drawing matplotlib figures off screen, as every figure of dtd is drawn, and keeping a sweep's
figures as PNG and SVG side by side (the key-frame strips and heatmaps of an explained run are
PNG only)."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def pyplot() -> Any:
    """matplotlib's pyplot, drawing off screen (Agg) as every figure of dtd is drawn. Imported
    when a figure is first drawn, so that commands that draw nothing never load matplotlib."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(figure: Any, path_stem: Path) -> list[Path]:
    """Write ``figure`` as ``path_stem``.png and .svg, close it, and return the two paths."""
    plt = pyplot()
    path_stem.parent.mkdir(parents=True, exist_ok=True)
    written = []
    for suffix in (".png", ".svg"):
        path = path_stem.with_suffix(suffix)
        figure.savefig(path, dpi=120)
        written.append(path)
    plt.close(figure)
    return written
