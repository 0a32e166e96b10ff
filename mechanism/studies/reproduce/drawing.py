"""Small drawing and formatting helpers of the report (four-panel figures, number formats, verdict words), and
how its figures are written: ``FigureFiles`` draws them in forked processes while the report goes on, and
skips a figure whose file was drawn from the same inputs (``inputs_key``)."""
from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np

from mechanism.output.atomic import atomic_open, save_figure as save_figure_atomic  # noqa: E402
from mechanism.output.workers import ForkedSaves

#: resolution of the report's figures [dots per inch]
DPI = 110
#: zlib level 1: a few percent larger files, several times faster to encode than the default 6 (as the run's plots)
PNG_OPTIONS = {"compress_level": 1}
#: the sources that draw the report's figures (their bytes are part of ``inputs_key``)
DRAWING_SOURCES = ("mechanism/studies/reproduce", "mechanism/output")
#: the file in the figures' folder that holds the ``inputs_key`` the figures there were drawn from
KEY_FILE = ".inputs-key"


def draw_figure(fig, path: Path) -> None:
    """Lay ``fig`` out (tight) and write it to ``path`` as PNG (atomically). The figure gets the file's resolution
    first, so that the layout and the drawing measure the text with one renderer (measured once)."""
    fig.set_dpi(DPI)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=DPI, pil_kwargs=PNG_OPTIONS)


def inputs_key(runs: dict, version: str) -> str:
    """SHA-256 (hex) over everything the report's figures are drawn from: each run's name, columns, samples, meta
    and status, the runs' code version, the drawing code's sources (``DRAWING_SOURCES``), matplotlib's and
    numpy's versions and matplotlib's settings. Equal keys draw byte-identical figures."""
    root = Path(__file__).resolve().parents[3]
    h = hashlib.sha256()
    h.update(f"{version}\0matplotlib=={matplotlib.__version__}\0numpy=={np.__version__}\0".encode())
    h.update(repr(sorted((k, repr(v)) for k, v in matplotlib.rcParams.items())).encode())
    for folder in DRAWING_SOURCES:
        for path in sorted((root / folder).glob("*.py")):
            h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    for name in sorted(runs):
        r = runs[name]
        h.update(json.dumps([name, list(r.columns), r.status, r.meta], sort_keys=True, default=repr).encode())
        h.update(np.ascontiguousarray(r.data).tobytes())
    return h.hexdigest()


def end_progress_monitor() -> None:
    """End tqdm's monitor thread if no bar is open: it outlives the runs' progress bar, and a process with another
    thread draws its figures in-process (``ForkedSaves``). The next bar starts it again."""
    std = sys.modules.get("tqdm.std")
    monitor = getattr(getattr(std, "tqdm", None), "monitor", None)
    if monitor is not None and not getattr(std.tqdm, "_instances", True):
        monitor.exit()
        std.tqdm.monitor = None


class FigureFiles:
    """The report's figures written while the report goes on: ``save`` hands a built figure to a forked process
    (``ForkedSaves``, at most ``processes`` at once: by default one per CPU, none on one) and returns. If the folder's ``KEY_FILE`` holds ``key``, a
    figure whose file is there is not drawn again (its inputs did not change: the same bytes). The key is removed
    before any figure is drawn and written when all are complete, so it never stands for a half-drawn folder.
    Use as a context manager; ``save_figure`` writes through the one that is open."""

    def __init__(self, folder: Path, key: str, processes: int | None = None):
        self.folder = Path(folder)
        self.key = key
        end_progress_monitor()
        if processes is None:   # one per CPU; on a single CPU nothing would draw beside this process
            processes = cpu if (cpu := os.cpu_count() or 1) >= 2 else 0
        self.saves = ForkedSaves(processes, draw_figure)
        self.skipped: list[str] = []
        self.drawn: list[str] = []
        key_file = self.folder / KEY_FILE
        self.current = key_file.is_file() and key_file.read_text().strip() == key
        self._key_removed = False

    def save(self, fig, path: Path) -> None:
        path = Path(path)
        if self.current and path.is_file():
            self.skipped.append(path.name)
            return
        if not self._key_removed:   # a figure is drawn: until all are complete the key stands for none
            with contextlib.suppress(FileNotFoundError):
                (self.folder / KEY_FILE).unlink()
            self._key_removed = True
        self.saves.submit(fig, path)
        self.drawn.append(path.name)

    def __enter__(self):
        global _FILES
        self._previous, _FILES = _FILES, self
        self.folder.mkdir(parents=True, exist_ok=True)
        return self

    def __exit__(self, kind, *exc):
        global _FILES
        _FILES = self._previous
        self.saves.__exit__(kind, *exc)     # every child reaped; their error raised if nothing else was
        if kind is None:
            with atomic_open(self.folder / KEY_FILE) as f:
                f.write(self.key + "\n")
        return False


_FILES: FigureFiles | None = None


def save_figure(fig, path: Path) -> str:
    """Write ``fig`` to ``path`` (``draw_figure``; through the open ``FigureFiles``, if any) and close it;
    returns the file's name."""
    path = Path(path)
    if _FILES is None:
        draw_figure(fig, path)
    else:
        _FILES.save(fig, path)
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
