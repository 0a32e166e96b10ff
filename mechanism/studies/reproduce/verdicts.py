"""The report's verdicts: the criteria (written at the top of the report), one verdict per figure and
window (steady revolution, start-up), and the summary table. A verdict is computed from the numbers
the figure's text gives, never written by hand."""
from __future__ import annotations

from dataclasses import dataclass

#: the start-up window: the first START_REVS crank revolutions (the journal falls through the clearance)
START_REVS = 0.1
#: "alike in size": a ratio of two magnitudes within these bounds
ALIKE = (0.8, 1.25)
#: "close to the ideal joint": the bearing's peak within this factor of the ideal joint's
CLOSE_TO_IDEAL = 1.25
STEADY = "steady (revolution 2)"
STARTUP = f"start-up (first {START_REVS:g} rev)"

#: (name, what it means) — printed at the top of the report
CRITERIA = [
    ("Windows", f"*{STEADY}*: the second crank revolution [T, 2T], the periodic motion the paper's claims "
                f"describe; *{STARTUP}*: the start, where the journal, released at the housing centre at full "
                "crank speed, falls through the clearance and strikes the balls. Every figure has a verdict for "
                "the steady window; the claims about impacts also one for the start-up."),
    ("Trends", "\"grows / decreases with X\" holds when the measure is strictly monotone over all the paper's "
               "values of X (300, 600, 900, 1200 rpm; or 8, 15, 20 balls)."),
    ("Alike in size", f"a ratio of two magnitudes within {ALIKE[0]:g} … {ALIKE[1]:g}."),
    ("Close to the ideal joint", f"the bearing's peak within {CLOSE_TO_IDEAL:g} × the ideal joint's in the window."),
    ("Magnitudes against the paper", "the paper's kg·mm·s units converted to SI (units section); a magnitude "
                                     "agrees when it fills 50–100 % of the paper's axis range."),
    ("Verdict words", "*agrees*: every check of the figure holds; *agrees in part*: some hold (the text says "
                      "which); *differs*: none holds; *not decided*: the runs cannot decide (e.g. too short). Where we differ from the paper, *believed right* says which "
                      "result we trust and why."),
    ("Accuracy of our numbers", "co-simulation at h = 1e-5 s with the default scheme (law-model, "
                                "docs/coupling.md, \"The default scheme and step\"): whole-run figures, start-up "
                                "included, within 0.03 % of the monolithic reference at every operating point of the "
                                "paper (300-1200 rpm, 8, 15 and 20 balls), except the 300 rpm slider-acceleration "
                                "maximum, which is ill-conditioned in the reference itself (46-62 m/s^2 as its "
                                "tolerance and integrator change). Pointwise measures at 300 rpm (RMS deviations, zero "
                                "crossings) follow contact-event timing and carry more uncertainty than peaks."),
]


@dataclass
class Verdict:
    figure: str
    window: str
    result: str          # agrees | agrees in part | differs
    criterion: str
    believed: str = ""


def result_of(checks: list[bool]) -> str:
    """agrees (all hold), agrees in part (some), differs (none); not decided without a check."""
    if not checks:
        return "not decided"
    if all(checks):
        return "agrees"
    return "agrees in part" if any(checks) else "differs"


def criteria_lines() -> list[str]:
    lines = ["## Criteria of the verdicts", ""]
    lines += [f"- **{name}**: {text}" for name, text in CRITERIA]
    return lines + [""]


def summary_lines(verdicts: list[Verdict]) -> list[str]:
    lines = ["## Verdicts", "", "| figure | window | verdict | criterion | believed right |", "|---|---|---|---|---|"]
    def cell(text: str) -> str:
        return text.replace("|", "\\|")
    for v in verdicts:
        lines.append(f"| {v.figure} | {cell(v.window)} | **{v.result}** | {cell(v.criterion)} | "
                     f"{cell(v.believed) or '—'} |")
    return lines + [""]
