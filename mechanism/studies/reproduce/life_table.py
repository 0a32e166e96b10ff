"""The reproduction report's bearing-life table (issue 16, docs/bearing-life.md): a ``Report`` mixin."""
from __future__ import annotations

import math

from mechanism.output.life import run_life
from mechanism.studies.reproduce.analysis import crank_period, n_balls_of
from mechanism.studies.reproduce.drawing import fmt


def _life(x) -> str:
    return "∞" if x == math.inf else fmt(x)


class LifeSection:
    """``section_life``: L10r per ball-bearing run, over the steady cycle and the whole run."""

    def section_life(self):
        rows = []
        for name in self.specs:
            r = self.runs.get(name)
            if r is None or not r.ok:
                continue
            whole = run_life(r)                         # the FMU's final outputs
            if whole is None:                           # not a ball-bearing run
                continue
            T = crank_period(r)
            half = 0.5 * float(r.meta.get("output_interval_s") or 0.0) + 1e-12   # the step count is rounded
            steady = run_life(r, (T, 2 * T)) if r["time"][-1] >= 2 * T - half else None
            rows.append((name, r.meta["config"]["rpm"], n_balls_of(r), steady, whole))
        if not rows:
            return
        w = self.w
        w("## Bearing rating life per operating point")
        w()
        first = rows[0][4]
        lives = [(row[3]["rating_life_h"], row[0]) for row in rows if row[3] is not None]
        w("Reference rating life L10r (ISO/TS 16281, a_1 = 1, 90 % reliability) from the simulated ball loads "
          "(docs/bearing-life.md): Q_ei, Q_ee are the equivalent rolling-element loads of the inner and outer "
          "ring; the outer ring (housing, on the crank) turns faster than the inner ring (on the rod) and is taken "
          "as the ring rotating relative to the load. *Steady cycle*: the second crank revolution, from the "
          "recorded ball loads (sampled every step) with the FMU's accumulator class; *whole run*: the FMU's final "
          "outputs, start-up transient included. Ratings of the Table 2 geometry: "
          f"C_r = {first['dynamic_load_rating_N']:.0f} N (ISO 281), Q_ci = {first['raceway_rating_inner_N']:.0f} N, "
          f"Q_ce = {first['raceway_rating_outer_N']:.0f} N (ISO/TS 16281) for {rows[0][2]} balls"
          + (f"; the shortest steady-cycle life is {min(lives)[0]:.3g} h (`{min(lives)[1]}`)." if lives else ".")
          + " Runs with 15 and 20 balls are hypothetical (the balls overlap) and rated as if they fitted.")
        w()
        w("| run | rpm | balls | Q_ei [N] | Q_ee [N] | L10r [10⁶ rev] | L10r [h] | whole run: L10r [h] |")
        w("|---|---|---|---|---|---|---|---|")
        for name, rpm, nb, steady, whole in rows:
            if steady is None:
                w(f"| `{name}` | {rpm:g} | {nb} | – | – | – | – | {_life(whole['rating_life_h'])} |")
                continue
            w(f"| `{name}` | {rpm:g} | {nb} | {fmt(steady['equivalent_load_inner_N'])} | "
              f"{fmt(steady['equivalent_load_outer_N'])} | {_life(steady['rating_life_Mrev'])} | "
              f"{_life(steady['rating_life_h'])} | {_life(whole['rating_life_h'])} |")
        w()
