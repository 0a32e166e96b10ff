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


# ---------------------------------------------------------------------------------------------- runs
def _cosim(scheme, step, revs, rpm=1200.0, output_interval=None, **kw):
    r = run(RunConfig(mode="inprocess", rpm=rpm, revs=revs, step=step, scheme=scheme, progress=False,
                      settings=DAMPING, output_interval=output_interval or max(step, 1e-5), **kw))
    assert r.ok, r.message
    return r


@pytest.fixture(scope="module")
def reference_fifth():
    """Monolithic reference, 0.2 revolution (10 ms, the start-up impacts) at 1200 rpm, rtol 1e-11."""
    r = run(RunConfig(mode="monolithic", revs=0.2, rtol=1e-11, progress=False, settings=DAMPING))
    assert r.ok, r.message
    return r
