"""Writing matplotlib figures the way every figure of dtd is kept: PNG and SVG side by side."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def save_figure(figure: Any, path_stem: Path) -> list[Path]:
    """Write ``figure`` as ``path_stem``.png and .svg, close it, and return the two paths."""
    import matplotlib.pyplot as plt

    path_stem.parent.mkdir(parents=True, exist_ok=True)
    written = []
    for suffix in (".png", ".svg"):
        path = path_stem.with_suffix(suffix)
        figure.savefig(path, dpi=120)
        written.append(path)
    plt.close(figure)
    return written
