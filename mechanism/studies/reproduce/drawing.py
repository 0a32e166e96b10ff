"""Small drawing and formatting helpers of the report (four-panel figures, number formats, verdict words)."""
from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from mechanism.output.atomic import save_figure as save_figure_atomic  # noqa: E402




def save_figure(fig, path: Path) -> str:
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)
    return path.name


def pi_axis(ax):
    ax.set_xlabel("crank angle [π rad]")
    ax.grid(alpha=0.3)


def four_panels(runs: dict, names: list[str], draw, title: str, path: Path, ylabel: str, sharey=False) -> str:
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.5), sharey=sharey)
    for ax, name in zip(axes.flat, names):
        if name in runs:
            draw(ax, name)
        ax.set_title(name)
        ax.set_ylabel(ylabel)
    fig.suptitle(title)
    return save_figure(fig, path)


def fmt(x, digits=3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return f"{x:.{digits}g}"


def verdict_word(ok: bool) -> str:
    """A check's outcome in the text (the figure's verdict is ``Report.verdict``)."""
    return "*holds*" if ok else "*does not hold*"


def increasing(values: list[float]) -> bool:
    return all(b > a for a, b in zip(values, values[1:]))


def decreasing(values: list[float]) -> bool:
    return all(b < a for a, b in zip(values, values[1:]))


# --- the report ------------------------------------------------------------------------------------
