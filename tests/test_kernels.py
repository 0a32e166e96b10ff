"""The compiled paths against their references: force models against ``Scheme.force``, the numba
multibody kernels against the NumPy ``System``, the compiled force law against ``BallBearing``."""
from __future__ import annotations

import random

import pytest

from mechanism.cosim.coupling import SCHEMES, Exchanged, make_scheme


def _exchange(rng: random.Random, t: float) -> Exchanged:
    k = [rng.uniform(-1e7, 1e7) for _ in range(3)]
    c = [rng.uniform(-1e2, 1e2) for _ in range(3)]
    return Exchanged(t, *(rng.uniform(-2e-5, 2e-5) for _ in range(2)), *(rng.uniform(-0.1, 0.1) for _ in range(2)),
                     *(rng.uniform(-500, 500) for _ in range(2)), *k, *c)


@pytest.mark.parametrize("name", sorted(SCHEMES))
@pytest.mark.parametrize("history", [1, 2, 3])
def test_force_model_equals_scheme_force(name, history):
    """Every registered scheme's ``force_model`` gives its ``force`` (the compiled step evaluates the former)."""
    rng = random.Random(hash((name, history)) & 0xFFFF)
    scheme = make_scheme(name)
    h = 1e-5
    for n in range(history):
        scheme.push(_exchange(rng, n * h * (1.0 + 0.3 * n)))   # uneven steps (the adaptive driver)
    t0 = scheme.past[-1].t
    scheme.begin_step(t0, h)
    model = scheme.force_model(t0, h)
    if model is None:
        pytest.skip(f"{name} has no force model (it runs through the Python path)")
    for _ in range(20):
        tau = t0 + rng.uniform(0.0, h)
        args = (tau, rng.uniform(-2e-5, 2e-5), rng.uniform(-2e-5, 2e-5), rng.uniform(-0.1, 0.1),
                rng.uniform(-0.1, 0.1))
        ref, got = scheme.force(*args), model(*args)
        scale = max(1.0, abs(ref[0]), abs(ref[1]))
        assert abs(got[0] - ref[0]) <= 1e-12 * scale and abs(got[1] - ref[1]) <= 1e-12 * scale


# ------------------------------------------------------------------------------ multibody kernels
import math  # noqa: E402

import numpy as np  # noqa: E402

from mechanism.cosim.coupling.base import ForceModel  # noqa: E402
from mechanism.cosim.joint import BearingLink  # noqa: E402
from mechanism.multibody import kernels as kn  # noqa: E402
from mechanism.multibody.compiled import CompiledSystem  # noqa: E402
from mechanism.multibody.integrators import rk4_step  # noqa: E402
from mechanism.multibody.model import GROUND, Body, Model, Point, Revolute, Translational  # noqa: E402
from mechanism.multibody.solver import System  # noqa: E402
from mechanism.systems import double_pendulum, four_bar, slider_crank  # noqa: E402


def _collar() -> tuple[System, np.ndarray, np.ndarray, float]:
    """A pendulum with a collar sliding along it: a translational joint whose axis turns with body i."""
    model = Model(bodies=(Body("arm", 0.5, 4e-3), Body("collar", 0.2, 1e-4)),
                  joints=(Revolute("pivot", Point(GROUND, (0.0, 0.0)), Point("arm", (-0.15, 0.0))),
                          Translational("slide", Point("arm", (0.0, 0.0)), Point("collar", (0.0, 0.0)),
                                        axis=(1.0, 0.2), angle0=0.3)),
                  gravity=(0.0, -9.81))
    s = System(model)
    th = -1.0
    q = s.assemble(np.array([0.15 * math.cos(th), 0.15 * math.sin(th), th, 0.2 * math.cos(th), 0.2 * math.sin(th),
                             th + 0.3]), 0.0)
    return s, q, s.velocities(q, 0.0, np.array([0.0, 0.0, 2.0, 0.0, 0.0, 2.0])), 0.5


def _models():
    """(name, system, q0, qd0, period [s] of one 'revolution') of the test models."""
    out = []
    for joint in ("ideal", "bearing"):
        p = slider_crank.SliderCrankParameters()
        s = System(slider_crank.build(p, joint))
        out.append((f"slider-crank-{joint}", s, *slider_crank.initial_state(s, p), 60.0 / p.rpm))
    for joint in ("ideal", "bearing"):
        p = four_bar.FourBarParameters()
        s = System(four_bar.build(p, joint))
        out.append((f"four-bar-{joint}", s, *four_bar.initial_state(s, p), 60.0 / p.rpm))
    s = System(double_pendulum.build())
    out.append(("double-pendulum", s, *double_pendulum.initial_state(s), 1.0))
    out.append(("collar", *_collar()))
    return out


MODELS = {m[0]: m[1:] for m in _models()}


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


@pytest.mark.parametrize("name", sorted(MODELS))
def test_kernel_accelerations_match_numpy_on_random_states(name):
    """Eq. (9) with Baumgarte terms: kernels and NumPy System agree to 1e-12 relative on random states."""
    system, q0, qd0, _ = MODELS[name]
    compiled = CompiledSystem(system)
    rng = np.random.default_rng(7)
    for _ in range(25):
        q = q0 + rng.normal(0.0, 1e-2, system.n)          # off the constraint manifold: Baumgarte terms act
        qd = qd0 + rng.normal(0.0, 1.0, system.n)
        Q = rng.normal(0.0, 50.0, system.n)
        t = rng.uniform(0.0, 0.1)
        ref_qdd, ref_lam = system.accelerations(q, qd, t, Q)
        qdd, lam = compiled.accelerations(q, qd, t, Q)
        assert _rel(qdd, ref_qdd) <= 1e-12
        assert _rel(lam, ref_lam) <= 1e-12
        assert np.max(np.abs(compiled.phi(q, t) - system.phi(q, t))) <= 1e-15 * (1 + np.max(np.abs(q)))


@pytest.mark.parametrize("contact_points", ["centres", "eq15"])
@pytest.mark.parametrize("name", ["slider-crank-bearing", "four-bar-bearing"])
def test_kernel_bearing_link_matches_numpy(name, contact_points):
    """Inputs (eq. 10-12) and generalized forces (eq. 20-23) of the force joint, through the compiled rhs."""
    system, q0, qd0, _ = MODELS[name]
    link = BearingLink(system, system.model.bearings[0], contact_points)
    ints, reals = kn.pack(system)
    L, LR = kn.pack_link(system, link.joint, contact_points)
    W, u = np.zeros(kn.workspace_size(ints)), np.zeros(6)
    rng = np.random.default_rng(3)
    fm = ForceModel(0.01, (120.0, -40.0), (3e4, -2e4), (1e6, 5e5), (2e-6, -1e-6), (0.01, 0.03),
                    (2e7, 3e6, 4e7), (150.0, 20.0, 300.0))
    for _ in range(10):
        y = np.concatenate((q0, qd0)) + rng.normal(0.0, 2e-5, 2 * system.n)
        tau = rng.uniform(0.01, 0.01001)
        q, qd = y[: system.n], y[system.n:]
        e = link.inputs(q, qd)
        Q = system.applied_forces(q, qd, tau)
        link.generalized_force(q, e[0], e[1], *fm(tau, *e[:4]), Q)
        ref = np.concatenate((qd, system.accelerations(q, qd, tau, Q)[0]))
        dy = np.empty(2 * system.n)
        kn.rhs(tau, y, fm.coefficients, ints, reals, L, LR, W, u, dy)
        assert np.allclose(u, e, rtol=0, atol=1e-15 * 1e3)
        assert _rel(dy, ref) <= 1e-12


@pytest.mark.parametrize("name", sorted(MODELS))
def test_kernel_trajectory_matches_numpy(name):
    """0.2 revolution (0.2 s for the free models) of RK4: kernels and NumPy System agree to 1e-9 relative."""
    system, q0, qd0, period = MODELS[name]
    link = BearingLink(system, system.model.bearings[0]) if system.model.bearings else None
    ints, reals = kn.pack(system)
    L, LR = kn.pack_link(system, link.joint if link else None)
    W, u = np.zeros(kn.workspace_size(ints)), np.zeros(6)
    # a stiff linear spring-damper in the bearing (F on the housing = K e + C v) (a jacobian force model about e = 0) keeps it assembled
    fm = ForceModel(0.0, (0.0, 0.0), K=(1e6, 0.0, 1e6), C=(50.0, 0.0, 50.0)) if link else None
    coeffs = fm.coefficients if fm else np.zeros(17)
    n = system.n

    def f(t, y):
        q, qd = y[:n], y[n:]
        Q = system.applied_forces(q, qd, t)
        if link is not None:
            e = link.inputs(q, qd)
            link.generalized_force(q, e[0], e[1], *fm(t, *e[:4]), Q)
        return np.concatenate((qd, system.accelerations(q, qd, t, Q)[0]))

    h = 1e-4 if link is None else 2e-5
    steps = int(round(0.2 * period / h))
    y_ref = y = np.concatenate((q0, qd0))
    for k in range(steps):
        y_ref = rk4_step(f, k * h, y_ref, h)
        y = y.copy()
        violation, finite = kn.advance(y, k * h, h, 1, (k + 1) * h, coeffs, y, False, ints, reals, L, LR, W, u)
        assert finite and violation < 1e-6
    assert _rel(y, y_ref) <= 1e-9
    assert _rel(y[:n], y_ref[:n]) <= 1e-9


# ------------------------------------------------------------------------------ compiled force law
from fmu_bearing.ball_bearing import BallBearing  # noqa: E402
from fmu_bearing.parameters import BearingParameters  # noqa: E402
from mechanism.cosim import law_kernel  # noqa: E402


@pytest.mark.parametrize("settings", [{}, {"n_balls": 20, "allow_ball_overlap": True}, {"damping_model": 2}, {"damping_model": 0}])
def test_compiled_force_law_matches_ball_bearing(settings):
    """The numba force law against the reference ``BallBearing.evaluate`` (eq. 18-19, 29-32) to 1e-12."""
    bearing = BallBearing(BearingParameters(**settings))
    P = law_kernel.pack_bearing(bearing)
    out, loads = np.empty(10), np.empty(bearing.n_balls)
    ref_loads = [0.0] * bearing.n_balls
    rng = np.random.default_rng(11)
    loaded = 0
    for _ in range(200):
        args = (*rng.uniform(-4e-5, 4e-5, 2), *rng.uniform(-0.3, 0.3, 2), rng.uniform(-7, 7),
                rng.uniform(-130, 130), rng.uniform(-130, 130))
        ref = bearing.evaluate(*args, ref_loads)
        law_kernel.evaluate(P, *args, out, loads)
        scale_f, scale_k = max(1.0, abs(ref.F_x), abs(ref.F_y)), max(1.0, abs(ref.k_xx), abs(ref.k_yy))
        scale_c = max(1e-9, abs(ref.c_xx), abs(ref.c_yy))
        assert abs(out[0] - ref.F_x) <= 1e-12 * scale_f and abs(out[1] - ref.F_y) <= 1e-12 * scale_f
        assert np.all(np.abs(out[2:5] - np.array(ref[2:5])) <= 1e-12 * scale_k)
        assert np.all(np.abs(out[5:8] - np.array(ref[5:8])) <= 1e-12 * scale_c)
        assert out[8] == ref.loaded_balls and abs(out[9] - ref.max_ball_load) <= 1e-12 * scale_f
        assert np.allclose(loads, ref_loads, rtol=1e-12, atol=1e-12 * scale_f)
        loaded += ref.loaded_balls > 0
    assert loaded > 50           # the draws reach the load zone


# ------------------------------------------------------------------------------ the master on the kernels
from mechanism.cosim.adaptive import AdaptiveSettings, run_adaptive  # noqa: E402
from mechanism.cosim.endpoints import InProcessEndpoint  # noqa: E402
from mechanism.cosim.master import MasterSettings, run_master  # noqa: E402
from mechanism.cosim.record import resample  # noqa: E402


def _slider_crank_run(scheme: str | None, kernels: bool, t_end: float = 0.0015, step: float = 1e-5):
    p = slider_crank.SliderCrankParameters()
    system = System(slider_crank.build(p, "ideal" if scheme is None else "bearing"))
    q0, qd0 = slider_crank.initial_state(system, p)
    settings = MasterSettings(t_end=t_end, step=step, output_interval=step, scheme=scheme or "zoh", progress=False,
                              kernels=kernels)
    observe = slider_crank.slider_crank_observer(system)
    if scheme is None:
        return run_master(system, q0, qd0, settings, observe, reaction_force=slider_crank.ideal_reaction(system))
    link = BearingLink(system, system.model.bearings[0])
    # the reference: the NumPy solver and the force law of fmu_bearing; the compiled run: kernels and law_kernel
    return run_master(system, q0, qd0, settings, observe, link, InProcessEndpoint(compiled=kernels))


@pytest.mark.parametrize("scheme", [None, *sorted(SCHEMES)])
def test_master_on_kernels_reproduces_the_numpy_master(scheme):
    """Same scheme, same step: the compiled master (kernels, compiled law, shared end-of-step evaluation,
    preallocated recording) gives the reference master's samples to 1e-9 relative per column."""
    ref = _slider_crank_run(scheme, kernels=False)
    got = _slider_crank_run(scheme, kernels=True)
    # (zoh-jacobi diverges at this step: both must stop at the same step with the same cause)
    assert (got.status, got.message) == (ref.status, ref.message)
    assert ref.columns == got.columns and ref.data.shape == got.data.shape and len(ref.data) > 50
    for k, column in enumerate(ref.columns):
        a, b = got.data[:, k], ref.data[:, k]
        assert np.array_equal(np.isnan(a), np.isnan(b)), column
        scale = np.nanmax(np.abs(b)) if np.isfinite(b).any() else 0.0
        tol = 1e-9 * scale + (1e-15 if column == "constraint_violation" else 0.0)
        assert np.nanmax(np.abs(a - b), initial=0.0) <= tol, column
    assert got.meta["substeps_total"] == ref.meta["substeps_total"]


def test_adaptive_driver_on_kernels_reproduces_the_numpy_master():
    """The adaptive scheme with rollback (snapshot/restore) on the kernels: same accepted steps and samples."""
    results = []
    for kernels in (False, True):
        p = slider_crank.SliderCrankParameters()
        system = System(slider_crank.build(p, "bearing"))
        q0, qd0 = slider_crank.initial_state(system, p)
        settings = AdaptiveSettings(t_end=0.001, output_interval=1e-4, tol=1e-3, step=1e-6, progress=False,
                                    kernels=kernels)
        results.append(run_adaptive(system, q0, qd0, settings, slider_crank.slider_crank_observer(system),
                                    BearingLink(system, system.model.bearings[0]), InProcessEndpoint(compiled=kernels)))
    ref, got = results
    assert ref.ok and got.ok
    assert got.meta["accepted_steps"] == ref.meta["accepted_steps"] and got.meta["rejected_steps"] == ref.meta["rejected_steps"]
    k = ref.columns.index("F_x")
    assert np.allclose(got.data[:, k], ref.data[:, k], rtol=0, atol=1e-9 * np.max(np.abs(ref.data[:, k])))


def test_ideal_counterpart_at_the_coarse_step_resamples_to_1e_6():
    """``run``'s ideal counterpart at 1e-4 s, resampled by cubic splines, against RK4 at 1e-5 s."""
    fine = _slider_crank_run(None, kernels=True, t_end=0.02, step=1e-5)
    coarse = resample(_slider_crank_run(None, kernels=True, t_end=0.02, step=1e-4), fine["time"])
    for column in ("slider_x", "slider_v", "slider_a", "crank_moment", "F_x", "F_y"):
        err = np.max(np.abs(coarse[column] - fine[column])) / np.max(np.abs(fine[column]))
        assert err < 1e-6, (column, err)


def test_kernel_redundant_constraints_give_the_numpy_accelerations():
    """A repeated joint makes Phi_q rank-deficient: the kernel drops the redundant rows (a basic solution for
    lambda), the NumPy reference takes the minimum-norm one; the accelerations are the same."""
    p = double_pendulum.DoublePendulumParameters()
    base = double_pendulum.build(p)
    pivot = base.joints[0]
    model = Model(bodies=base.bodies, joints=(*base.joints, Revolute("pivot_again", pivot.i, pivot.j)),
                  gravity=base.gravity)
    system = System(model)
    q, qd = double_pendulum.initial_state(System(base), p)
    qd = System(base).velocities(q, 0.0, np.array([0.0, 0.0, 1.0, 0.0, 0.0, -2.0]))
    Q = np.array([1.0, -2.0, 0.1, 0.5, 0.3, -0.05])
    ref_qdd, ref_lam = system.accelerations(q, qd, 0.0, Q)
    qdd, lam = CompiledSystem(system).accelerations(q, qd, 0.0, Q)
    assert _rel(qdd, ref_qdd) <= 1e-10
    J = system.jacobian(q)
    assert np.allclose(J.T @ lam, J.T @ ref_lam, rtol=1e-10, atol=1e-10 * np.max(np.abs(J.T @ ref_lam)))


def test_compiled_elastic_energy_is_ball_bearings_at_the_load_zones_edge():
    """``law_kernel.elastic_energy`` (which settles the balls clearly out of the load zone from one cos and sin)
    equals ``BallBearing.elastic_energy`` bit for bit with e at the clearance (balls at the load zone's edge), cage
    angles up to 1e4 rad."""
    bearing = BallBearing(BearingParameters())
    P = law_kernel.pack_bearing(bearing)
    rng = np.random.default_rng(13)
    half = bearing.half_clearance
    loaded = 0
    for trial in range(3000):
        phase, radius = rng.uniform(0, 2 * math.pi), half * (1 + rng.normal(0, 0.02))
        ex, ey = radius * math.cos(phase), radius * math.sin(phase)
        cage = rng.uniform(-7, 7) if trial % 2 else rng.uniform(-1e4, 1e4)
        ref = bearing.elastic_energy(ex, ey, cage)
        assert law_kernel.elastic_energy(P, ex, ey, cage) == ref, trial
        loaded += ref > 0
    assert loaded > 500


@pytest.mark.parametrize("settings", [{}, {"n_balls": 20, "allow_ball_overlap": True}])
def test_compiled_elastic_energy_matches_ball_bearing_and_is_the_hertz_potential(settings):
    """``law_kernel.elastic_energy`` (the energy account's V) equals ``BallBearing.elastic_energy`` to
    1e-12, and its gradient in e (central differences) is the law's elastic force (eq. 18-19 at v = 0)."""
    bearing = BallBearing(BearingParameters(**settings))
    P = law_kernel.pack_bearing(bearing)
    out, loads = np.empty(10), np.empty(bearing.n_balls)
    rng = np.random.default_rng(12)
    loaded = 0
    for _ in range(200):
        ex, ey, cage = *rng.uniform(-4e-5, 4e-5, 2), rng.uniform(-7, 7)
        ref = bearing.elastic_energy(ex, ey, cage)
        got = law_kernel.elastic_energy(P, ex, ey, cage)
        assert abs(got - ref) <= 1e-12 * max(ref, 1e-30)
        law_kernel.evaluate(P, ex, ey, 0.0, 0.0, cage, 0.0, 0.0, out, loads)
        d = 1e-11
        grad = [(law_kernel.elastic_energy(P, ex + d, ey, cage) - law_kernel.elastic_energy(P, ex - d, ey, cage)) / (2 * d),
                (law_kernel.elastic_energy(P, ex, ey + d, cage) - law_kernel.elastic_energy(P, ex, ey - d, cage)) / (2 * d)]
        scale = max(1.0, abs(out[0]), abs(out[1]))
        assert np.allclose(grad, out[:2], rtol=0, atol=1e-4 * scale), (grad, out[:2])   # F = dV/de
        loaded += ref > 0
    assert loaded > 50
