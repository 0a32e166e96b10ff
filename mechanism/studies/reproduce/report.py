"""Figures and the generated report of ``python -m mechanism reproduce`` (``DIR/report/README.md``).

Everything here is computed from the cached runs: the measured figures, each paper claim's
check ("agrees" / "differs"), the stiffness-variant comparison and the modelling choices, whose
numbers are read from the code (``BearingParameters``, ``hertz``, ``solver``, ...).  The paper's
own numbers (axis ranges of its figures, converted from its kg-mm-s units) are the constants of
``PAPER``.  Never edit the README by hand: rerun the command.

The report is one ``Report`` assembled from mixins: ``SpeedFigures`` (Fig. 11-19), ``DesignFigures``
(Fig. 20-25), ``Sections`` (runs, units, stiffness variant, modelling choices) and ``LifeSection``
(bearing rating life per operating point).

The figures are written by ``drawing.FigureFiles``: in forked processes while the text is assembled, and not
at all when the folder's figures were drawn from the same inputs (``drawing.inputs_key``: the runs' samples and
meta, the drawing code, the package versions). So ``--force`` recomputes every run, and the figures are drawn
again exactly when a recomputed run (or the code that draws) came out different."""
from __future__ import annotations

import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

from mechanism.cosim.record import RunResult  # noqa: E402
from mechanism.output.plots import crank_pi  # noqa: E402
from mechanism.studies.reproduce.analysis import (figures_of)  # noqa: E402
from mechanism.studies.reproduce.drawing import FigureFiles, four_panels, inputs_key, pi_axis  # noqa: E402
from mechanism.studies.reproduce.cases import (BALL_COUNTS, SPEEDS, STUDY_RPM, paper_stiffness)  # noqa: E402
from mechanism.studies.reproduce.figures_design import (DesignFigures)  # noqa: E402
from mechanism.studies.reproduce.figures_speed import (SpeedFigures)  # noqa: E402
from mechanism.studies.reproduce.life_table import (LifeSection)  # noqa: E402
from mechanism.studies.reproduce.sections import (Sections)  # noqa: E402
from mechanism.studies.reproduce.verdicts import Verdict, criteria_lines, summary_lines  # noqa: E402


class Report(SpeedFigures, DesignFigures, Sections, LifeSection):
    """The generated README of the reproduction: figures, measured values and each claim's check."""

    def __init__(self, out: Path, specs, outcome: dict):
        self.out = Path(out)
        self.dir = self.out / "report"
        self.fig_dir = self.dir / "figures"
        self.fig_dir.mkdir(parents=True, exist_ok=True)
        self.specs = {s.name: s for s in specs}
        self.runs: dict[str, RunResult] = {n: r for n, r in outcome["results"].items() if len(r["time"]) > 1}
        self.infos = outcome["infos"]
        self.outcome = outcome
        self.lines: list[str] = []
        self.missing: list[str] = []
        self.verdicts: list[Verdict] = []

    # helpers
    def has(self, *names) -> bool:
        ok = all(n in self.runs for n in names)
        if not ok:
            self.missing += [n for n in names if n not in self.runs and n not in self.missing]
        return ok

    def ideal_of(self, name: str) -> RunResult | None:
        rpm = self.runs[name].meta["config"]["rpm"]
        return self.runs.get(f"ideal-{float(rpm):g}")

    def ideal_vs_bearing(self, names: list[str], col: str, title: str, filename: str, ylabel: str,
                         label: str = "ball bearing") -> str:
        """Four panels (one run each): ``col`` of the ideal joint (black) and of the run, against the crank angle."""
        def draw(ax, name):
            r, i = self.runs[name], self.ideal_of(name)
            ax.plot(crank_pi(i), i[col], "k", lw=1.2, label="ideal joint")
            ax.plot(crank_pi(r), r[col], lw=0.7, label=label)
            ax.legend(fontsize=7)
            pi_axis(ax)
        return four_panels(self.runs, names, draw, title, self.fig_dir / filename, ylabel)

    def w(self, text: str = "") -> None:
        self.lines.append(text)

    def verdict(self, figure: str, window: str, checks: list[bool], criterion: str, believed: str = "") -> None:
        """Record a figure's verdict (computed from ``checks``, see verdicts.result_of) and write its line."""
        from mechanism.studies.reproduce.verdicts import STEADY, result_of
        revs = min((spec.config.revs for spec in self.specs.values()), default=2.0)
        if window == STEADY and revs < 2.0:
            window = f"whole run ({revs:g} rev: no second revolution)"
        v = Verdict(figure, window, result_of(checks), criterion, believed)
        self.verdicts.append(v)
        self.w(f"**Verdict ({figure}, {window}): {v.result}.** Criterion: {criterion}."
               + (f" *Believed right:* {believed}" if believed else ""))
        self.w()

    def figure(self, fname: str, caption: str) -> None:
        self.w(f"![{caption}](figures/{fname})")
        self.w()
        self.w(f"*{caption}*")
        self.w()

    # ------------------------------------------------------------------------------------------
    def build(self) -> Path:
        self.speeds = [f"{s:g}" for s in SPEEDS]
        self.bearing = [f"bearing-{s}" for s in self.speeds]
        self.ideal = [f"ideal-{s}" for s in self.speeds]
        self.paperK = [f"paperK-{s}" for s in self.speeds]
        self.balls = {n: (f"bearing-{STUDY_RPM:g}" if n == 8 else f"bearing-{STUDY_RPM:g}-{n}balls") for n in BALL_COUNTS}
        self.clear = f"clearance-{STUDY_RPM:g}"
        self.b1200, self.i1200 = f"bearing-{STUDY_RPM:g}", f"ideal-{STUDY_RPM:g}"
        self.K_paper = paper_stiffness()
        self.table = {n: figures_of(r, self.ideal_of(n) if not n.startswith("ideal") else None)
                      for n, r in self.runs.items()}

        w = self.w
        w("# Reproduction of Xu et al. (2012), Section 5")
        w()
        w("*Generated by `python -m mechanism reproduce` from the runs in `../cache/`; do not edit by hand.* "
          f"Generated {time.strftime('%Y-%m-%d %H:%M:%S')}, code version `{self.outcome['code_version'][:16]}`.")
        w()
        w("L. Xu, Y. Yang, Y. Li, C. Li, S. Wang, *Modeling and analysis of planar multibody systems containing deep "
          "groove ball bearing with clearance*, Mech. Mach. Theory 56 (2012) 69–88. Every bearing run is a co-simulation "
          "of the Python multibody master with a bearing FMU (BallBearing, or JournalClearance for Fig. 23–25) through "
          "fmpy; the ideal-joint runs use the same master with the ideal revolute joint and no component.")
        w()
        w("\n".join(criteria_lines()))
        summary_at = len(self.lines)          # the verdict table goes here once every figure has its verdict
        # the figures are drawn in forked processes while the text goes on (all complete when the block ends);
        # a figure drawn from the same inputs before is not drawn again
        with FigureFiles(self.fig_dir, inputs_key(self.runs, self.outcome.get("code_version", ""))):
            for section in self.sections():
                section()
        if self.missing:
            w("## Missing runs")
            w()
            w("These runs were not part of this reproduction (a limited run list) or recorded no samples; the "
              "figures and checks that need them are left out: " + ", ".join(f"`{m}`" for m in self.missing) + ".")
            w()
        self.lines[summary_at:summary_at] = summary_lines(self.verdicts)
        path = self.dir / "README.md"
        path.write_text("\n".join(self.lines) + "\n")
        return path

    def sections(self) -> list:
        """The report's sections in order (a study adds its own here, e.g. a life table)."""
        return [self.section_runs, self.section_life, self.section_units, self.section_figures,
                self.section_stiffness, self.section_choices]

    # ------------------------------------------------------------------------------------------

    def section_figures(self):
        w = self.w
        w("## Figures against the paper's claims")
        w()
        w("Each figure is followed by the paper's claim (quoted briefly), our numbers with the checks they pass or "
          "fail, and the figure's verdict from the criteria above. Default model: SI Hertz stiffness, constant damping "
          "(see the modelling choices).")
        w()
        for fn in (self.fig11, self.fig12, self.fig13, self.fig14, self.fig15, self.fig16, self.fig17_18,
                   self.fig19, self.fig20, self.fig21, self.fig22, self.fig23_24, self.fig25):
            fn()


def write_report(out: Path, specs, outcome: dict) -> Path:
    """Draw the figures and write ``out/report/README.md``; return its path."""
    return Report(out, specs, outcome).build()
