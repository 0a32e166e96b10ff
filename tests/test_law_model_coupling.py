"""The model-based coupling ``law-model`` (mechanism/cosim/coupling/law_model.py): the component's force law as
the interface model within a communication step, the exchanged force correcting it at both ends.

Unit tests hold the scheme's force against the law's one home (``fmu_bearing.ball_bearing.BallBearing.evaluate``);
the run tests hold it against the monolithic reference, as tests/test_coupling_order.py does for the default.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import from_values
from mechanism.cosim.coupling import Exchanged, make_scheme
from mechanism.cosim.record import energy_summary
from mechanism.run import RunConfig, run

DAMPING = {"damping_model": 1, "damping_coefficient": 50.0}


def _law(**settings) -> BallBearing:
    return BallBearing(from_values({**DAMPING, **settings}))


def _exchange(law: BallBearing, t: float, e, v, cage: float, offset=(0.0, 0.0)) -> Exchanged:
    """What a component with ``law`` returns at (e, v, cage), its force shifted by ``offset`` [N]."""
    out = law.evaluate(*e, *v, cage)
    return Exchanged(t, *e, *v, out.F_x + offset[0], out.F_y + offset[1], *out[2:8])


E0, V0 = (1.2e-5, -0.4e-5), (0.02, 0.03)        # in the load zone: two or three balls loaded
CAGE, W_IN, W_OUT = 0.3, 125.0, -20.0


def _scheme(law: BallBearing | None, x: Exchanged, h: float = 1e-4):
    scheme = make_scheme("law-model")
    scheme.push(x)
    scheme.bind_law(law)
    scheme.set_cage(CAGE, W_IN, W_OUT)
    scheme.begin_step(x.t, h)
    return scheme


def test_force_is_the_law_within_the_step():
    """An exact component (its force is the law's): the step's force is the law at (e, v) with the cage angle
    advanced by eq. (16) at the start's ring speeds, at any interface state, not only near the start."""
    law = _law()
    t0, h = 0.01, 1e-4
    scheme = _scheme(law, _exchange(law, t0, E0, V0, CAGE))
    omega = law.cage_velocity(W_IN, W_OUT)
    rng = np.random.default_rng(1)
    for _ in range(50):
        s = rng.uniform(0.0, h)
        e = (E0[0] + rng.uniform(-3e-6, 3e-6), E0[1] + rng.uniform(-3e-6, 3e-6))
        v = (rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1))
        ref = law.evaluate(*e, *v, CAGE + omega * s)
        got = scheme.force(t0 + s, *e, *v)
        assert math.hypot(got[0] - ref.F_x, got[1] - ref.F_y) <= 1e-9 * max(1.0, math.hypot(ref.F_x, ref.F_y))


def test_component_force_is_the_authority_at_both_ends():
    """A component whose force differs from the master's law (offset at the start, another offset at the end of
    the last pass): the step's force equals the component's at t_n and, on a repeated pass, at t_n + h; in between
    the law plus the linear ramp of the two corrections."""
    law = _law()
    t0, h = 0.0, 1e-4
    start = _exchange(law, t0, E0, V0, CAGE, offset=(3.0, -1.0))
    scheme = _scheme(law, start, h)
    got = scheme.force(t0, *E0, *V0)
    assert got == pytest.approx((start.F_x, start.F_y), rel=1e-12, abs=1e-9)
    omega = law.cage_velocity(W_IN, W_OUT)
    e1, v1 = (E0[0] + 1e-6, E0[1] + 2e-6), (0.01, -0.02)
    end = _exchange(law, t0 + h, e1, v1, CAGE + omega * h, offset=(-2.0, 4.0))
    scheme.set_trial(end)
    scheme.set_cage(CAGE, W_IN, W_OUT)
    scheme.begin_step(t0, h)
    assert scheme.force(t0, *E0, *V0) == pytest.approx((start.F_x, start.F_y), rel=1e-12, abs=1e-9)
    assert scheme.force(t0 + h, *e1, *v1) == pytest.approx((end.F_x, end.F_y), rel=1e-12, abs=1e-9)
    mid = law.evaluate(*e1, *v1, CAGE + omega * h / 2)
    assert scheme.force(t0 + h / 2, *e1, *v1) == pytest.approx((mid.F_x + 0.5, mid.F_y + 1.5), rel=1e-12, abs=1e-9)


def test_without_a_law_it_is_the_default_scheme():
    """No law bound (a component the master does not know): the force model of ``jacobian-implicit``."""
    law = _law()
    x = _exchange(law, 0.0, E0, V0, CAGE)
    scheme, default = _scheme(None, x), make_scheme("jacobian-implicit")
    default.push(x)
    default.begin_step(0.0, 1e-4)
    assert scheme.force_model(0.0, 1e-4) is not None
    for tau, e, v in ((0.0, E0, V0), (5e-5, (1.3e-5, -0.3e-5), (0.0, 0.05))):
        assert scheme.force(tau, *e, *v) == default.force(tau, *e, *v)


def test_substeps_follow_the_stiffest_tangent_of_the_step():
    """A step that starts out of contact but is predicted to enter it is sized by the law's tangent there."""
    law = _law()
    e_free, v_in = (0.0, 0.995 * law.half_clearance), (0.0, 0.05)    # just inside the clearance, closing at 5 cm/s
    x = _exchange(law, 0.0, e_free, v_in, CAGE)
    assert x.k_yy == 0.0
    scheme = _scheme(law, x, 1e-4)
    bound = scheme.substep_tangent()
    ref = law.evaluate(e_free[0], e_free[1] + 1e-4 * v_in[1], *v_in, CAGE + law.cage_velocity(W_IN, W_OUT) * 1e-4)
    r = scheme.resolution
    assert ref.k_yy > 0.0 and bound.k_yy == pytest.approx(r * r * ref.k_yy, rel=1e-12)
    assert bound.c_yy == pytest.approx(r * ref.c_yy, rel=1e-12)


def _rk4_with_onset(theta: float, j: float, d: float, g0: float, g1: float, h: float = 1.0):
    """One RK4 step of x'' = f(t) + g0 + g1 t / h from rest, f switched on at theta h with the value j, growing by
    d per step: RK4 samples f at t = 0, h/2, h/2, h (the master's stages for a force of time alone)."""
    def f(t):
        return (j + d * (t / h - theta) if t > theta * h else 0.0) + g0 + g1 * t / h

    def rhs(t, y):
        return np.array([y[1], f(t)])
    y = np.zeros(2)
    k1 = rhs(0.0, y)
    k2 = rhs(h / 2, y + h / 2 * k1)
    k3 = rhs(h / 2, y + h / 2 * k2)
    k4 = rhs(h, y + h * k3)
    return y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _onset_implementations(name):
    """``name`` of law_model (the reference) and of law_model_kernel (its numba twin, which the compiled loop calls)."""
    from mechanism.cosim import law_model_kernel
    from mechanism.cosim.coupling import law_model
    return [getattr(law_model, name), getattr(law_model_kernel, name)]


@pytest.mark.parametrize("which", [0, 1], ids=["python", "numba"])
@pytest.mark.parametrize("theta", [0.05, 0.3, 0.49, 0.51, 0.8, 0.97])
def test_onset_weights_make_rk4_exact_for_the_jump(theta, which):
    """A force switched on inside an RK4 step (eq. 18's damping jump, then growing): without the correction RK4's
    velocity and position are off by O(j h) and O(j h^2); with ``onset_weights``' g0 + g1 sigma both equal the
    exact integrals (closed form: v = j r + d r^2 / 2, x = j r^2 / 2 + d r^3 / 6, r = 1 - theta, h = 1)."""
    onset_weights = _onset_implementations("onset_weights")[which]
    j, d = 2.0, 0.7
    r = 1.0 - theta
    exact = np.array([j * r * r / 2 + d * r ** 3 / 6, j * r + d * r * r / 2])
    plain = _rk4_with_onset(theta, j, d, 0.0, 0.0)
    corrected = _rk4_with_onset(theta, j, d, *tuple(onset_weights(theta, j, d)))
    assert np.max(np.abs(plain - exact)) > 1e-2
    assert corrected == pytest.approx(exact, abs=1e-14)


@pytest.mark.parametrize("which", [0, 1], ids=["python", "numba"])
def test_onset_fraction_is_the_root_of_the_deflection(which):
    """A deflection that is a cubic in the substep (the Hermite interpolant through its end values and rates is
    then exact): the onset is its root, not the linear interpolation's."""
    onset_fraction = _onset_implementations("onset_fraction")[which]

    def delta(s):
        return (s - 0.3) * (s + 0.5) * (3.0 - s) * 1e-7

    def rate(s):
        return ((s + 0.5) * (3.0 - s) + (s - 0.3) * (3.0 - s) - (s - 0.3) * (s + 0.5)) * 1e-7
    linear = delta(0.0) / (delta(0.0) - delta(1.0))
    assert abs(linear - 0.3) > 0.1
    assert onset_fraction(delta(0.0), delta(1.0), rate(0.0), rate(1.0)) == pytest.approx(0.3, abs=1e-12)


# ---------------------------------------------------------------------------------------------- runs
def _cosim(scheme, step, revs, rpm=1200.0, output_interval=None, mode="inprocess", **kw):
    r = run(RunConfig(mode=mode, rpm=rpm, revs=revs, step=step, scheme=scheme, progress=False,
                      settings=DAMPING, output_interval=output_interval or max(step, 1e-5), **kw))
    assert r.ok, r.message
    return r


@pytest.fixture(scope="module")
def reference_fifth():
    """Monolithic reference, 0.2 revolution (10 ms, the start-up impacts) at 1200 rpm, rtol 1e-11."""
    r = run(RunConfig(mode="monolithic", revs=0.2, rtol=1e-11, progress=False, settings=DAMPING))
    assert r.ok, r.message
    return r


def _errors(r, ref) -> tuple[float, float]:
    """(pointwise |F| error over the second half of the window relative to the reference's peak there, max cage-angle
    error [rad]), the run sampled on a multiple of the reference's 1e-5 s grid."""
    t_ref, F_ref = ref["time"], np.hypot(ref["F_x"], ref["F_y"])
    half = t_ref >= 0.5 * t_ref[-1]
    idx = np.rint(r["time"] / 1e-5).astype(int)
    F = np.hypot(r["F_x"], r["F_y"])
    sel = half[idx]
    return (float(np.max(np.abs(F - F_ref[idx])[sel]) / np.max(F_ref[half])),
            float(np.max(np.abs(r["cage_angle"] - ref["cage_angle"][idx]))))


def test_compiled_onset_corrections_match_the_reference_at_the_load_zones_edge():
    """The compiled onset corrections (``law_model_kernel.onset_corrections``, which settles the balls far from the
    load zone's edge from one cos and sin per substep bound) against the reference
    (``LawModel._onset_corrections``), bit for bit: random substeps with e at the clearance (balls entering and
    leaving the load zone), cage angles up to 1e4 rad, several substep counts."""
    from mechanism.cosim import law_model_kernel as lmk
    from mechanism.cosim.law_kernel import pack_bearing
    law = _law()
    P = pack_bearing(law)
    half = law.half_clearance
    rng = np.random.default_rng(11)
    onsets_seen = 0
    for trial in range(1500):
        m, h = int(rng.integers(1, 6)), 10 ** rng.uniform(-6, -4)
        cage = rng.uniform(-7, 7) if trial % 2 else rng.uniform(-1e4, 1e4)
        wi, wo = rng.uniform(-130, 130), rng.uniform(-20, 20)
        phase, radius = rng.uniform(0, 2 * math.pi), half * (1 + rng.normal(0, 0.05))
        points = []
        for _ in range(m + 1):
            a, r = phase + rng.normal(0, 0.1), radius * (1 + rng.normal(0, 0.02))
            points.append((r * math.cos(a), r * math.sin(a), *rng.normal(0, 0.02, 2)))
        end = Exchanged(h, *points[m], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        scheme = make_scheme("law-model")
        scheme.bind_law(law)
        scheme.set_cage(cage, wi, wo)
        scheme._h_step = h
        reference = scheme._onset_corrections(m, dict(enumerate(points[:m])), end)
        LM = np.zeros(lmk.LM_SIZE)
        lmk.set_cage(LM, P, cage, wi, wo)
        LM[1] = h
        onsets = np.full((m, 5), np.nan)
        lmk.onset_corrections(LM, P, m, np.array(points), np.array([h, *points[m], *[0.0] * 8]), onsets)
        for k in range(m):
            if k in reference:
                assert onsets[k, 4] == 1.0 and tuple(onsets[k, :4]) == reference[k], (trial, k)
            else:
                assert onsets[k, 4] == 0.0 and not onsets[k, :4].any(), (trial, k)
        onsets_seen += len(reference)
    assert onsets_seen > 100


def test_at_1e_4_s_the_error_is_the_substeps_not_the_step(reference_fifth, monkeypatch):
    """h = 1e-4 s over the start-up (0.2 revolution at 1200 rpm, impacts and contact onsets): the law-model's
    error is its RK4 substeps' (it falls with ``resolution``), far below jacobian-implicit's at the same step.
    Measured (onset correction of impulse and first moment, 2026-11-26): pointwise |F| 2.0e-2 and 8.6e-4 of the
    peak at resolution 1 and 8 (the default); cage angle 1.5e-6 and 7.7e-8 rad; jacobian-implicit at 1e-4 s: 0.41
    of the peak, 5.3e-5 rad."""
    from mechanism.cosim.coupling.law_model import LawModel
    default = _errors(_cosim("jacobian-implicit", 1e-4, 0.2), reference_fifth)
    errors = {}
    for resolution in (1.0, 8.0):
        monkeypatch.setattr(LawModel, "resolution", resolution)
        errors[resolution] = _errors(_cosim("law-model", 1e-4, 0.2), reference_fifth)
    print("jacobian-implicit", default, "law-model", errors)
    assert errors[8.0][0] < errors[1.0][0] / 10 and errors[8.0][1] < errors[1.0][1] / 10, errors
    assert errors[8.0][0] < default[0] / 5 and errors[8.0][1] < default[1] / 5, (errors, default)


def test_energy_residual_at_1e_4_s():
    """The energy the coupling creates (``energy_residual_coupling_J``: the work of the force the mechanism felt
    against what the law stores and dissipates along the trajectory) over the start-up at 1e-4 s: within 1 % of
    the dissipation for the law-model (measured 3.0e-7 J, 6.7e-5 of D = 4.4 mJ), the default scheme at that step
    -6.3e-4 J (-14 % of D)."""
    law_model = _cosim("law-model", 1e-4, 0.2)
    default = _cosim("jacobian-implicit", 1e-4, 0.2)
    D = energy_summary(law_model)["damping_dissipation_J"]
    R, R_default = (r.meta["energy_residual_coupling_J"] for r in (law_model, default))
    print(f"D = {D:.4g} J, R law-model {R:.3g} J, jacobian-implicit {R_default:.3g} J")
    assert D > 1e-3
    assert abs(R) <= 0.01 * D
    assert abs(R) < abs(R_default) / 5


def test_law_model_through_the_fmu(ball_bearing_fmu):
    """Through the FMU (fmpy; rollback by getFMUstate/setFMUstate; the law from the master's own parameters) the
    samples equal the in-process path's: the FMU stays the authority at every communication point."""
    a = _cosim("law-model", 1e-4, 0.05, mode="cosim", fmu=str(ball_bearing_fmu))
    b = _cosim("law-model", 1e-4, 0.05)
    for col in ("F_x", "F_y", "e_x", "cage_angle", "energy_residual"):
        scale = max(1e-30, float(np.max(np.abs(b[col]))))
        assert np.max(np.abs(a[col] - b[col])) <= 1e-9 * scale, col
    assert a.meta["iteration_not_converged"] == 0
