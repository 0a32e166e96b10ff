"""Writing a file so that it is either its old content or complete (issue 14): a temporary name beside the
target, renamed onto it when the write has finished, removed when it failed."""
from __future__ import annotations

import contextlib
import os
from pathlib import Path


@contextlib.contextmanager
def _replacing(path: Path, tmp: Path):
    """Yield ``tmp``; rename it onto ``path`` when the block ends without an exception, else remove it."""
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_open(path: Path, mode: str = "w", **kwargs):
    """``open(path, mode)`` on a temporary name beside ``path``, renamed to ``path`` when the block ends
    without an exception (removed otherwise): ``path`` is either its old content or complete."""
    path = Path(path)
    with _replacing(path, path.with_name(f".{path.name}.{os.getpid()}.tmp")) as tmp, open(tmp, mode, **kwargs) as f:
        yield f


def save_figure(fig, path: Path, **kwargs) -> Path:
    """``fig.savefig(path, **kwargs)`` on a temporary name beside ``path`` (same extension, so matplotlib
    picks the format), renamed to ``path`` when complete: a PNG is either its old content or whole."""
    path = Path(path)
    with _replacing(path, path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")) as tmp:
        fig.savefig(tmp, **kwargs)
    return path


def save_canvas(canvas, path: Path, **pil_kwargs) -> Path:
    """The picture an Agg ``canvas`` holds (drawn already: nothing is drawn again) as a PNG at ``path`` (with
    matplotlib's PNG metadata), written as ``save_figure`` writes: either the old content or whole."""
    import matplotlib
    from PIL import Image, PngImagePlugin
    path = Path(path)
    rgba = canvas.buffer_rgba()
    info = PngImagePlugin.PngInfo()
    info.add_text("Software", f"Matplotlib version{matplotlib.__version__}, https://matplotlib.org/")
    image = Image.frombuffer("RGBA", (rgba.shape[1], rgba.shape[0]), rgba, "raw", "RGBA", 0, 1)
    dpi = canvas.figure.dpi
    with _replacing(path, path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")) as tmp:
        image.save(tmp, format="png", pnginfo=info, dpi=(dpi, dpi), **pil_kwargs)
    return path
