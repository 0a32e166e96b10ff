"""Issue 12: the second-order and iterated coupling schemes, the energy account, contact onsets.

Short runs (0.05-0.1 revolution at 1200 rpm) through the in-process endpoint where it equals the
FMU path (``test_secant_and_iterated_schemes_through_the_fmu`` holds the two together). The energy
account's own tests are in tests/test_energy.py.
"""
from __future__ import annotations

import numpy as np
import pytest

from mechanism.cosim.record import energy_summary
from mechanism.output.results import summary
from mechanism.run import RunConfig, run, run_adaptive
from mechanism.studies.stepsize.tables import observed_order

DAMPING = {"damping_model": 1, "damping_coefficient": 50.0}


def _cosim(scheme, step, revs=0.1, mode="inprocess", **kw):
    r = run(RunConfig(mode=mode, revs=revs, step=step, scheme=scheme, progress=False, settings=DAMPING, **kw))
    assert r.ok, r.message
    return r


@pytest.fixture(scope="module")
def reference_fifth():
    """Monolithic reference, 0.2 revolution (10 ms, the start-up impacts) at 1200 rpm, rtol 1e-11."""
    r = run(RunConfig(mode="monolithic", revs=0.2, rtol=1e-11, progress=False, settings=DAMPING))
    assert r.ok, r.message
    return r


def test_jacobian_implicit_is_second_order_through_the_start_up(reference_fifth):
    """Issue 12 item 5 for ``jacobian-implicit`` (the default scheme until law-model took over; the default's
    own order is tests/test_law_model_order.py), on the first 0.2 revolution at 1200 rpm (start-up impacts and
    contact onsets included), steps 2e-5 ... 2.5e-6 s: observed order >= 1.8 on the cage angle
    and on the peak joint force of the second half of the window, against the monolithic reference.
    (The issue's window is the second revolution; measured there by docs/coupling.md's command:
    order 1.94 on the cage angle and 1.82 on the rev-2 peak force, second order down to 5e-6 s and a
    floor of about 1e-4 of the peak below it.)"""
    scheme = "jacobian-implicit"
    ref = reference_fifth
    t_ref = ref["time"]
    half = t_ref >= 0.5 * t_ref[-1]
    ref_peak = float(np.max(np.hypot(ref["F_x"], ref["F_y"])[half]))
    steps, cage, peak = [2e-5, 1e-5, 5e-6, 2.5e-6], [], []
    for h in steps:
        r = _cosim(scheme, h, revs=0.2)
        idx = np.rint(r["time"] / 1e-5).astype(int)          # h = 2e-5 samples every step
        cage.append(float(np.max(np.abs(r["cage_angle"] - ref["cage_angle"][idx]))))
        sel = half[idx]
        peak.append(abs(float(np.max(np.hypot(r["F_x"], r["F_y"])[sel])) / ref_peak - 1.0))
    print(f"cage errors {cage} order {observed_order(steps, cage):.2f}; peak errors {peak} order {observed_order(steps, peak):.2f}")
    assert observed_order(steps, cage) >= 1.8, cage
    assert observed_order(steps, peak) >= 1.8, peak


def test_secant_ring_speeds_remove_the_cage_angle_error(reference_fifth):
    """The FMU integrates the cage angle with the ring speeds held over the step: end-of-step speeds
    (jacobian-drift) are backward Euler, O(h); the secant speeds (jacobian-secant) make it exact up to
    the mechanism's error. Against the reference's integrated eq. (16)."""
    errors = {}
    for scheme in ("jacobian-drift", "jacobian-secant"):
        for h in (1e-5, 5e-6):
            r = _cosim(scheme, h)
            ref = reference_fifth["cage_angle"][: len(r["time"])]           # both sampled every 1e-5 s
            errors[scheme, h] = float(np.max(np.abs(r["cage_angle"] - ref)))
    # backward Euler: first order, error halves with the step
    assert 1.7 < errors["jacobian-drift", 1e-5] / errors["jacobian-drift", 5e-6] < 2.3, errors
    # the secant speeds remove it: what is left is the mechanism's own error in the ring angles
    # (measured 7.8e-7 / 3.1e-7 rad against 1.6e-5 / 8.2e-6: 20x smaller, but converging at order ~1.3
    # only, as the trajectory does through the contact onsets)
    assert errors["jacobian-secant", 1e-5] < errors["jacobian-drift", 1e-5] / 10, errors
    assert errors["jacobian-secant", 5e-6] < errors["jacobian-secant", 1e-5], errors


def test_secant_and_iterated_schemes_through_the_fmu(ball_bearing_fmu):
    """Through the FMU (fmpy; rollback by getFMUstate/setFMUstate) the samples equal the in-process path's,
    the iterated scheme reports its passes and converges in every step."""
    for scheme in ("jacobian-secant", "jacobian-implicit"):
        a = _cosim(scheme, 1e-5, revs=0.05, mode="cosim", fmu=str(ball_bearing_fmu))
        b = _cosim(scheme, 1e-5, revs=0.05)
        for col in ("F_x", "F_y", "e_x", "cage_angle", "energy_residual"):
            scale = max(1e-30, float(np.max(np.abs(b[col]))))
            assert np.max(np.abs(a[col] - b[col])) <= 1e-9 * scale, (scheme, col)
    assert a.meta["iteration_passes_mean"] > 1.0
    assert a.meta["iteration_not_converged"] == 0
    assert a.meta["component_calls"] == round(a.meta["iteration_passes_mean"] * 250)


def test_energy_account_measures_the_coupling_error():
    """The residual of a co-simulation falls with the step: the explicit extrapolation extrap1 creates energy
    (R > 0) at third order here (measured over 0.1 revolution at 1200 rpm: 2.5e-4 J at 1e-5 s, 3.8e-6 J at
    2.5e-6 s, against D = 3.3 mJ); the account's own error (tests/test_energy.py) is far below both."""
    coarse, fine = (energy_summary(_cosim("extrap1", h)) for h in (1e-5, 2.5e-6))
    assert coarse["energy_residual_J"] > 0.02 * coarse["damping_dissipation_J"], coarse
    assert coarse["energy_residual_J"] > 20 * abs(fine["energy_residual_J"]), (coarse, fine)


def test_iterated_scheme_is_stable_at_1e_4_s():
    """jacobian-implicit at h = 1e-4 s, 1200 rpm, 0.4 revolution (the start-up impacts included): it runs
    through (jacobian-drift fails there, its limit is ~3e-5 s). Its fixed point does not always converge
    to 1e-7 in 8 passes at this step (contact onsets within a step make the pass-to-pass map
    oscillate); the run counts those steps and accepts the last pass."""
    r = _cosim("jacobian-implicit", 1e-4, revs=0.4)
    assert r.meta["iteration_not_converged"] < 200 and r.meta["iteration_passes_max"] <= 8
    print("not converged:", r.meta["iteration_not_converged"], "of 200")
    assert np.max(np.hypot(r["e_x"], r["e_y"])) < 1e-4
    bad = run(RunConfig(mode="inprocess", revs=0.4, step=1e-4, scheme="jacobian-drift", progress=False,
                        settings=DAMPING))
    assert not bad.ok


def test_adaptive_refines_through_contact_onsets():
    """With contact_step the adaptive driver rejects steps across which the loaded-ball set changes;
    the onsets are resolved to contact_step."""
    plain = run_adaptive(RunConfig(mode="inprocess", revs=0.04, progress=False, settings=DAMPING), 1e-3)
    onset = run_adaptive(RunConfig(mode="inprocess", revs=0.04, progress=False, settings=DAMPING), 1e-3,
                         contact_step=2e-7)
    assert plain.ok and onset.ok
    assert onset.meta["contact_rejections"] > 0 and plain.meta["contact_rejections"] == 0
    assert onset.meta["min_step_s"] <= 2e-7 < plain.meta["min_step_s"]


def test_default_scheme_energy_residual_within_1_percent_of_dissipation():
    """Issue 12's target: the default scheme at its default step, two revolutions at 1200 rpm (8 balls, C = 50
    N s/m per ball): |R| <= 1 % of the dissipated energy. Measured +0.0025 % (R = +0.12 uJ, D = 4.90 mJ) for
    law-model at 1e-5 s (jacobian-implicit: -0.42 % at 1e-5 s, -0.12 % at 5e-6 s) with the account integrated by
    the master's RK4 stages; the old account (quadrature of the samples) showed +143 %, its own error
    (docs/coupling.md, "Energy account")."""
    from mechanism.cosim.coupling import DEFAULT_SCHEME
    from mechanism.run import DEFAULT_STEP
    assert (DEFAULT_SCHEME, DEFAULT_STEP) == ("law-model", 1e-5)
    r = run(RunConfig(mode="inprocess", revs=2, progress=False, settings=DAMPING))
    assert r.ok, r.message
    e = energy_summary(r)
    assert e["damping_dissipation_J"] > 4e-3
    assert abs(e["energy_residual_J"]) <= 0.01 * e["damping_dissipation_J"], e


def test_summary_json_has_the_energy_account():
    r = _cosim("jacobian-drift", 1e-5, revs=0.05)
    s = summary(r)
    assert s["energy"]["damping_dissipation_J"] > 0
    assert {"energy_residual", "drive_work", "contact_energy", "cage_work"} <= set(r.columns)


def test_monolithic_reference_figures_do_not_move_with_its_tolerance():
    """Issue 12: tightening the reference's tolerance (rtol 1e-9 -> 1e-10, contact onsets located as events)
    changes no reported figure by more than 0.1 % (start-up impacts, 0.1 revolution at 1200 rpm; measured
    spread <= 1.1e-4 over rtol 1e-9 ... 1e-11 on 0.2 revolution, the slider-acceleration maximum, the rest
    <= 1.3e-6). The constraint violation is excluded: it is the tolerance's own footprint."""
    figures = []
    for rtol in (1e-9, 1e-10):
        r = run(RunConfig(mode="monolithic", revs=0.1, rtol=rtol, progress=False, settings=DAMPING))
        assert r.ok, r.message
        assert r.meta["contact_events"] > 10
        figures.append(summary(r)["all"])
    for key, coarse in figures[0].items():
        if key == "max_constraint_violation_m":
            continue
        fine = figures[1][key]
        assert abs(coarse - fine) <= 1e-3 * abs(fine), (key, coarse, fine)


def _implicit_master(t_end: float, **settings):
    from mechanism.cosim.endpoints import InProcessEndpoint
    from mechanism.cosim.joint import BearingLink
    from mechanism.cosim.master import MasterSettings, run_master
    from mechanism.multibody.solver import System
    from mechanism.systems import slider_crank
    p = slider_crank.SliderCrankParameters(rpm=1200)
    model = slider_crank.build(p, "bearing")
    system = System(model)
    q0, qd0 = slider_crank.initial_state(system, p)
    ms = MasterSettings(t_end=t_end, step=1e-5, scheme="jacobian-implicit", progress=False, **settings)
    r = run_master(system, q0, qd0, ms, slider_crank.slider_crank_observer(system), BearingLink(system, model.bearings[0]),
                   InProcessEndpoint(DAMPING))
    assert r.ok, r.message
    return r


def test_iterating_only_where_needed_stays_at_the_fixed_point():
    """``iterate_where_needed`` (default) accepts a pass when the predicted change of a further pass is within
    iteration_tol (1e-7) instead of repeating until two passes agree. Over the start-up impacts (0.4 revolution
    at 1200 rpm, h = 1e-5 s) it saves passes (measured 2.92 -> 2.05 per step; each saved pass is an FMU
    rollback) and stays within 1e-4 relative of the fixed point iterated to 1e-12 (measured, largest value of
    each column: F_x 5.9e-6, F_y 3.1e-5, e_y 2.1e-5, crank moment 1.1e-5; the old rule 5e-8 ... 1.5e-7), below
    the scheme's own error at this step (rev-2 pointwise force 5.0e-4, docs/coupling.md); the accuracy tests
    of the scheme (order, stability, 1 % targets) are unchanged and pass."""
    t_end = 0.02
    tight = _implicit_master(t_end, iteration_tol=1e-12, iterate_where_needed=False, max_iterations=20)
    old = _implicit_master(t_end, iterate_where_needed=False)
    new = _implicit_master(t_end)
    assert new.meta["iteration_passes_mean"] < old.meta["iteration_passes_mean"] - 0.5, (new.meta, old.meta)
    assert new.meta["iteration_predicted"] > 0 and new.meta["iteration_not_converged"] == 0
    for c in ("F_x", "F_y", "e_x", "e_y", "slider_a", "crank_moment"):
        scale = float(np.max(np.abs(tight[c])))
        print(c, float(np.max(np.abs(new[c] - tight[c]))) / scale, float(np.max(np.abs(old[c] - tight[c]))) / scale)
        assert np.max(np.abs(new[c] - tight[c])) <= 1e-4 * scale, c
