"""Issue 12 item 5 for ``law-model`` (mechanism/cosim/coupling/law_model.py): observed order >= 1.8 (and >= 2.5,
the third order docs/coupling.md states) on the cage angle
and on the second-revolution peak joint force, steps 2e-5 ... 2.5e-6 s, against the monolithic reference.

1200 rpm, 8 balls, C = 50 N s/m per ball, two revolutions, in-process endpoint (the FMU path equals it:
tests/test_law_model_coupling.py::test_law_model_through_the_fmu), compiled loop. The reference is LSODA at
rtol 1e-12 (its own spread, against rtol 1e-11: 6.8e-8 of the rev-2 peak, 6e-11 rad, below the finest errors here).
The rev-2 peak is compared on the run's own sample grid (a run at 2e-5 s samples every 2e-5 s; against the
reference's 1e-5 s grid its peak would carry a sampling error of 7e-4 that has nothing to do with the coupling).
Measured (2026-11-26; docs/coupling.md, "law-model's order"): cage angle 5.2e-7, 6.6e-9, 8.4e-9, 4.5e-10 rad
(fitted order 3.0), rev-2 peak 2.9e-4, 4.8e-6, 5.2e-6, 2.4e-7 (order 3.1).
"""
from __future__ import annotations

import numpy as np
import pytest

from mechanism.run import RunConfig, run
from mechanism.studies.stepsize.tables import observed_order

DAMPING = {"damping_model": 1, "damping_coefficient": 50.0}
STEPS = (2e-5, 1e-5, 5e-6, 2.5e-6)
REV = 0.05        # one crank revolution at 1200 rpm [s]


@pytest.fixture(scope="module")
def reference():
    """Monolithic reference, two revolutions at 1200 rpm, LSODA rtol 1e-12, samples every 1e-5 s."""
    r = run(RunConfig(mode="monolithic", revs=2, rtol=1e-12, progress=False, settings=DAMPING))
    assert r.ok, r.message
    return r


def test_law_model_is_third_order(reference):
    """The default scheme's order (issue 12 item 5): law-model is the default (DEFAULT_SCHEME)."""
    from mechanism.cosim.coupling import DEFAULT_SCHEME
    assert DEFAULT_SCHEME == "law-model"
    t_ref = np.asarray(reference["time"])
    F_ref = np.hypot(reference["F_x"], reference["F_y"])
    rev2 = t_ref >= REV - 1e-12
    cage, peak = [], []
    for h in STEPS:
        r = run(RunConfig(mode="inprocess", revs=2, step=h, scheme="law-model", progress=False, settings=DAMPING,
                          output_interval=max(h, 1e-5)))
        assert r.ok, r.message
        assert r.meta["iteration_not_converged"] == 0
        idx = np.rint(np.asarray(r["time"]) / 1e-5).astype(int)
        cage.append(float(np.max(np.abs(np.asarray(r["cage_angle"]) - np.asarray(reference["cage_angle"])[idx]))))
        sel = rev2[idx]
        F = np.hypot(r["F_x"], r["F_y"])
        peak.append(abs(float(np.max(F[sel])) / float(np.max(F_ref[idx][sel])) - 1.0))
    print(f"cage {cage} order {observed_order(STEPS, cage):.2f}; rev-2 peak {peak} order {observed_order(STEPS, peak):.2f}")
    assert observed_order(STEPS, cage) >= 1.8, cage
    assert observed_order(STEPS, peak) >= 1.8, peak
    # docs/coupling.md states "about third order" (fits 3.01 and 3.06): held here with a margin
    assert observed_order(STEPS, cage) >= 2.5 and observed_order(STEPS, peak) >= 2.5, (cage, peak)
    assert cage[-1] < cage[0] / 40 and peak[-1] < peak[0] / 40, (cage, peak)
