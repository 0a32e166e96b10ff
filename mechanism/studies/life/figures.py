"""The life study's figures: rating life and equivalent loads against clearance or speed (PNG)."""
from __future__ import annotations

import math
from pathlib import Path

from mechanism.output.atomic import save_figure


def plot(rows: list[dict], x: str, path: Path, title: str) -> None:
    """Rating life [h] (left) and the equivalent loads [N] (right) against ``x`` ("radial_clearance" or "rpm")."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ok = [r for r in rows if r["status"] == "completed" and math.isfinite(r["rating_life_h"])]
    scale, label = (1e6, "radial clearance P_d [µm]") if x == "radial_clearance" else (1.0, "crank speed [rpm]")
    xs = [r[x] * scale for r in ok]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    a.semilogy(xs, [r["rating_life_h"] for r in ok], "o-")
    a.set_xlabel(label)
    a.set_ylabel("rating life L10r [h]")
    a.grid(True, which="both", alpha=0.3)
    b.plot(xs, [r["equivalent_load_inner_N"] for r in ok], "o-", label="Q_ei (inner ring)")
    b.plot(xs, [r["equivalent_load_outer_N"] for r in ok], "s-", label="Q_ee (outer ring)")
    b.plot(xs, [r["max_ball_load_N"] for r in ok], "^--", label="max ball load")
    b.set_xlabel(label)
    b.set_ylabel("load [N]")
    b.legend()
    b.grid(True, alpha=0.3)
    if x == "radial_clearance":
        for ax in (a, b):
            ax.axvline(0.0, color="grey", lw=0.8)
            ax.axvline(20.0, color="grey", lw=0.8, ls=":")
    failed = len(rows) - len(ok)
    fig.suptitle(title + (f" ({failed} point(s) failed, not shown)" if failed else ""))
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
