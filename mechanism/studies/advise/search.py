"""The search of one operating point: per scheme, bisection on the step ladder for the largest stable
step and the largest step that meets the tolerance, both bracketed by a passing and a failing step.

The ladder is the set of steps the step-size study can compare on the reference's output grid
(``stepsize.cases.snap_step``): dt/k below the output interval dt, dt*k above it, between the
smallest step the cost cap allows and ``h_cap``, neighbours at least a ratio ``--resolution`` apart. Both properties are assumed monotone in the step
(a step that passes makes every smaller step pass): the search brackets the limit by a passing and a
failing rung and bisects the bracket (in log h) until the two rungs are neighbours on the ladder.
A limit above the largest rung or below the smallest is reported as a bound ("≥" / "<"), never as a
value.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from mechanism.studies.stepsize.cases import ERROR, SKIPPED, STABLE

#: figures of merit: name -> (row column of the relative error, what it is)
MERITS: dict[str, tuple[str, str]] = {
    "peak-force": ("peak_force_err_rel", "peak joint force |F| over the window"),
    "max-eccentricity": ("max_ecc_err_rel", "max eccentricity |e| over the window"),
    "max-ball-load": ("max_ball_load_err_rel", "max ball load over the window"),
    "slider-acceleration": ("err_slider_a_max_rel", "slider acceleration, max pointwise error / its peak"),
    "force-pointwise": ("err_force_max_rel", "joint force, max pointwise error / peak |F|"),
}
DEFAULT_MERIT = "peak-force"


def ladder(dt: float, h_min: float, h_cap: float, ratio: float = 1.0) -> list[float]:
    """The comparable steps in [h_min, h_cap], ascending: dt/k below dt and dt*k above it, thinned so that
    neighbours differ by at least ``ratio`` (1: every one); the largest comparable step <= h_cap is kept."""
    def ks(limit: float) -> list[int]:
        out, k = [], 1
        while k <= limit * (1 + 1e-9):
            out.append(k)
            k = max(k + 1, math.ceil(k * ratio - 1e-9))
        return out

    up = [dt * k for k in ks(h_cap / dt)]
    top = dt * math.floor(h_cap / dt + 1e-9)
    if top >= dt and up and top > up[-1] * (1 + 1e-9):
        up.append(top)
    down = [dt / k for k in ks(dt / h_min) if k > 1]
    return sorted(s for s in up + down if h_min * (1 - 1e-9) <= s <= h_cap * (1 + 1e-9))


def merit_error(row: dict, merits: list[str]) -> float | None:
    """The worst |relative error| over the chosen figures of merit (None when one is missing)."""
    errors = []
    for m in merits:
        v = row.get(MERITS[m][0])
        if v is None:
            return None
        errors.append(abs(v))
    return max(errors) if errors else None


@dataclass
class Bracket:
    """Indices into the ladder: ``ok`` the largest rung known to pass, ``bad`` the smallest known to fail
    (-1 / len(ladder) when none is known yet)."""

    ok: int
    bad: int

    @property
    def closed(self) -> bool:
        return self.bad - self.ok <= 1


@dataclass
class SchemeSearch:
    """The probes of one scheme and its two brackets (stability and tolerance)."""

    scheme: str
    ladder: list[float]
    start: int
    rows: dict[int, dict] = field(default_factory=dict)
    stable: Bracket = None
    within: Bracket = None
    error: str | None = None

    def __post_init__(self):
        n = len(self.ladder)
        self.stable, self.within = Bracket(-1, n), Bracket(-1, n)

    def record(self, index: int, row: dict, tol: float, merits: list[str]) -> None:
        """Add the probe at rung ``index`` and recompute both brackets from every probe so far."""
        self.rows[index] = row
        if row["status"] in (ERROR, SKIPPED):
            self.error = row.get("message") or row["status"]
            return
        stable = row["status"] == STABLE
        err = merit_error(row, merits) if stable else None
        row["merit_error"] = err
        row["within"] = bool(stable and err is not None and err <= tol)
        row["stable"] = stable
        for bracket, key in ((self.stable, "stable"), (self.within, "within")):
            failing = [i for i, r in self.rows.items() if "stable" in r and not r[key]]
            bracket.bad = min(failing, default=len(self.ladder))
            # the largest passing rung with no failure at or below it (a failure below a pass is not hidden)
            bracket.ok = max((i for i, r in self.rows.items() if "stable" in r and r[key] and i < bracket.bad),
                             default=-1)

    @property
    def non_monotone(self) -> bool:
        """A rung passed above a failing one (the assumption of the bisection does not hold there)."""
        return any(r.get("stable") and i > self.stable.bad for i, r in self.rows.items())

    def _probe(self, bracket: Bracket) -> int | None:
        n = len(self.ladder)
        if bracket.closed or self.error:
            return None
        if bracket.ok < 0 and bracket.bad >= n:
            return self.start
        if bracket.bad >= n:          # nothing failed yet: try the largest rung (large steps are cheap)
            return n - 1 if (n - 1) not in self.rows else None
        lo = max(bracket.ok, 0)
        target = math.sqrt(self.ladder[lo] * self.ladder[bracket.bad])
        inside = [i for i in range(bracket.ok + 1, bracket.bad) if i not in self.rows]
        if not inside:
            return None
        return min(inside, key=lambda i: abs(math.log(self.ladder[i] / target)))

    def next_probes(self) -> list[int]:
        """The rungs to run next: the midpoint of each open bracket (tolerance first), without repeats."""
        picks = []
        for bracket in (self.within, self.stable):
            i = self._probe(bracket)
            if i is not None and i not in picks:
                picks.append(i)
        return picks

    @property
    def done(self) -> bool:
        return bool(self.error) or not self.next_probes()

    def limit(self, which: str) -> dict:
        """The result of one bracket: the passing and failing rungs (steps [s]) and whether each is a bound."""
        b = self.stable if which == "stable" else self.within
        n = len(self.ladder)
        return {"step": self.ladder[b.ok] if b.ok >= 0 else None,
                "fails_at": self.ladder[b.bad] if b.bad < n else None,
                "above_range": b.ok == n - 1,            # passes at the largest rung: a lower bound
                "below_range": b.ok < 0 and b.bad == 0,  # fails at the smallest rung: an upper bound
                "row": self.rows.get(b.ok)}
