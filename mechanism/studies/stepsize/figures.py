"""The study's plots: error and cost against the step per scheme (PNG)."""
from __future__ import annotations

from pathlib import Path
import numpy as np
from mechanism.output.atomic import save_figure
from mechanism.studies.stepsize.cases import (ADAPTIVE, DIVERGENT, FAILED, NONFINITE, ONE_PERCENT, ORDER_METRIC, PEAK_METRIC, STABLE)
from mechanism.studies.stepsize.tables import (_axis)


# ----------------------------------------------------------------------------------------- plots
def plot_study(rows: list[dict], summary: dict, out: Path) -> list[Path]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for g, info in summary["groups"].items():
        rs = [r for r in rows if r["group"] == g]
        schemes = list(info["schemes"])
        colors = {s: plt.cm.tab10(i % 10) for i, s in enumerate(schemes)}
        fig, axes = plt.subplots(1, 2, figsize=(13, 5.2), sharex=True)
        for ax, metric, title in ((axes[0], ORDER_METRIC, "max |F − F_ref| / max |F_ref| over the window"),
                                  (axes[1], PEAK_METRIC, "peak error: max(|Δ peak |F||, |Δ max |e||), relative")):
            top = 1.0
            for s in schemes:
                pts = sorted((r for r in rs if r["scheme"] == s and r.get("step")), key=_axis)
                ok = [(r["step"], r[metric]) for r in pts if r["status"] == STABLE and r.get(metric)]
                bad = [r for r in pts if r["status"] in (FAILED, DIVERGENT, NONFINITE)]
                label = s
                o = info["schemes"][s]["order"]
                if metric == ORDER_METRIC and o.get("order") is not None:
                    label += f" (order {o['order']:.2f})"
                if s == ADAPTIVE:
                    label += " (x: mean step)"
                if ok:
                    ax.loglog(*zip(*ok), "o-", color=colors[s], label=label, ms=4, lw=1.2)
                else:
                    ax.plot([], [], "o-", color=colors[s], label=label)
                if metric == ORDER_METRIC and o.get("order") is not None:
                    xs = np.geomspace(*o["steps"], 20)
                    ax.loglog(xs, np.exp(o["intercept"]) * xs ** o["order"], "--", color=colors[s], lw=0.8)
                edge = top * 0.8 ** schemes.index(s)  # one row of markers per scheme
                for r in bad:  # unstable: marked near the top edge (divergent ones at their error if lower)
                    yv = r.get(metric) if r["status"] == DIVERGENT and r.get(metric) else edge
                    ax.loglog([r["step"]], [min(yv, edge)], "x", color=colors[s], ms=8, mew=2)
                limit = info["schemes"][s]["smallest_unstable_step_s"]
                if limit:
                    ax.axvline(limit, color=colors[s], ls=":", lw=1)
            ax.axhline(ONE_PERCENT, color="k", lw=0.6, ls="-.")
            ax.text(0.01, ONE_PERCENT * 1.1, "1 %", fontsize=8, transform=ax.get_yaxis_transform())
            ax.set_xlabel("communication step h [s] (adaptive: mean step)")
            ax.set_ylabel("relative error [1]")
            ax.set_title(title, fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
        axes[0].legend(fontsize=8, loc="lower right")
        fig.suptitle(f"{g}: error against step (× unstable: failed or > {summary['config']['divergence']:.0%}; "
                     "dotted: smallest unstable step)",
                     fontsize=11)
        fig.tight_layout()
        p = out / f"stepsize_error_vs_step_{g}.png"
        save_figure(fig, p, dpi=110)
        plt.close(fig)
        paths.append(p)
        fig, ax = plt.subplots(figsize=(7.5, 5.2))
        for s in schemes:
            pts = [(r["wall_time"], r[ORDER_METRIC]) for r in sorted(rs, key=lambda r: r["step"] or 0.0)
                   if r["scheme"] == s and r["status"] == STABLE and r.get(ORDER_METRIC) and r.get("wall_time")]
            if pts:  # joined in step order
                ax.loglog(*zip(*pts), "o-", color=colors[s], label=s, ms=4)
        ax.axhline(ONE_PERCENT, color="k", lw=0.6, ls="-.")
        ax.set_xlabel("wall time per case [s]")
        ax.set_ylabel("max relative force error [1]")
        ax.set_title(f"{g}: error against cost (stable runs)", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        fig.tight_layout()
        p = out / f"stepsize_error_vs_walltime_{g}.png"
        save_figure(fig, p, dpi=110)
        plt.close(fig)
        paths.append(p)
    return paths
