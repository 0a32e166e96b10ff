"""Tests of the generic planar multibody core against independent closed forms."""
from __future__ import annotations

import math

import numpy as np
import pytest

import closed_form as cf
from mechanism.multibody.integrators import rk4_step
from mechanism.multibody.model import GROUND, AngleDriver, Body, Model, Point, Revolute, Translational
from mechanism.systems.slider_crank import SliderCrankParameters, build, initial_state
from mechanism.multibody.solver import System

G = 9.81
PARAMS = SliderCrankParameters()          # Table 1, 1200 rpm
H = 1e-5                                  # RK4 step [s]
DRIFT_BOUND = 1e-10                       # max |Phi| allowed over one revolution [m, rad]


def reference(p: SliderCrankParameters = PARAMS) -> cf.Crank:
    return cf.Crank(r=p.crank_length, l=p.rod_length, m1=p.crank_mass, J1=p.crank_inertia,
                    m2=p.rod_mass, J2=p.rod_inertia, m3=p.slider_mass, omega=p.omega)


def state_derivative(system: System):
    """f(t, y) = [qd, qdd] for rk4_step, with applied forces from the model (gravity)."""
    n = system.n

    def f(t: float, y: np.ndarray) -> np.ndarray:
        q, qd = y[:n], y[n:]
        qdd, _ = system.accelerations(q, qd, t, system.applied_forces(q, qd, t))
        return np.concatenate((qd, qdd))
    return f


# --------------------------------------------------------------------------- the reference itself
@pytest.mark.parametrize("theta", [0.0, 0.3, 1.2, 2.5, 3.6, 5.1])
def test_closed_form_is_self_consistent(theta):
    """Guard the reference: analytic derivatives vs complex step, power vs Newton-Euler."""
    c = reference()
    h = 1e-30
    assert cf.slider_xd(c, theta) == pytest.approx(c.omega * np.imag(cf.slider_x(c, theta + 1j * h)) / h,
                                                   rel=1e-12, abs=1e-12)
    assert cf.slider_xdd(c, theta) == pytest.approx(c.omega * np.imag(cf.slider_xd(c, theta + 1j * h)) / h,
                                                    rel=1e-12, abs=1e-9)
    phid, phidd = cf.rod_rates(c, theta)
    assert phid == pytest.approx(c.omega * np.imag(cf.rod_angle(c, theta + 1j * h)) / h, rel=1e-12, abs=1e-12)
    assert phidd == pytest.approx(c.omega * np.imag(cf.rod_rates(c, theta + 1j * h)[0]) / h,
                                  rel=1e-12, abs=1e-9)
    ne = cf.newton_euler(c, theta)
    peak = max(abs(cf.crank_moment(c, th)) for th in np.linspace(0, 2 * np.pi, 64))
    assert abs(ne["moment"] - cf.crank_moment(c, theta)) < 1e-10 * peak


# --------------------------------------------------------------------------- one revolution, ideal joint
@pytest.fixture(scope="module")
def revolution():
    """The ideal slider-crank integrated with RK4 (h = 1e-5 s) over one crank revolution."""
    system = System(build(PARAMS, "ideal"))
    q0, qd0 = initial_state(system, PARAMS)
    f = state_derivative(system)
    steps = round(2 * math.pi / PARAMS.omega / H)
    y = np.concatenate((q0, qd0))
    rec = {"t": [], "q": [], "qdd": [], "lam": [], "phi": []}
    for k in range(steps + 1):
        t = k * H
        q, qd = y[: system.n], y[system.n:]
        qdd, lam = system.accelerations(q, qd, t, np.zeros(system.n))
        for key, val in (("t", t), ("q", q.copy()), ("qdd", qdd), ("lam", lam),
                         ("phi", np.max(np.abs(system.phi(q, t))))):
            rec[key].append(val)
        y = rk4_step(f, t, y, H)
    rec = {key: np.array(val) for key, val in rec.items()}
    rec["system"] = system
    return rec


def test_revolution_slider_position(revolution):
    c = reference()
    theta = c.omega * revolution["t"]
    assert np.max(np.abs(revolution["q"][:, 2] - theta)) < 1e-10           # driver holds theta = omega t
    err = np.max(np.abs(revolution["q"][:, 6] - cf.slider_x(c, theta)))
    assert err < 1e-9, f"slider position error {err:.3e} m"
    rod = np.max(np.abs(revolution["q"][:, 5] - cf.rod_angle(c, theta)))
    assert rod < 1e-9, f"rod angle error {rod:.3e} rad"


def test_revolution_slider_acceleration(revolution):
    c = reference()
    exact = cf.slider_xdd(c, c.omega * revolution["t"])
    rel = np.max(np.abs(revolution["qdd"][:, 6] - exact)) / np.max(np.abs(exact))
    assert rel < 1e-6, f"slider acceleration relative error {rel:.3e}"


def test_revolution_crank_moment_matches_power_balance(revolution):
    c, system = reference(), revolution["system"]
    exact = cf.crank_moment(c, c.omega * revolution["t"])
    moment = np.array([system.driving_moment(lam, "crank_driver") for lam in revolution["lam"]])
    rel = np.max(np.abs(moment - exact)) / np.max(np.abs(exact))
    assert rel < 1e-6, f"crank moment relative error {rel:.3e}"


def test_revolution_constraint_drift(revolution):
    drift = np.max(revolution["phi"])
    print(f"max |Phi| over one revolution at 1200 rpm, h = {H:g} s: {drift:.3e}")
    assert drift < DRIFT_BOUND, f"max |Phi| = {drift:.3e} exceeds {DRIFT_BOUND:g}"


def test_revolution_reactions_match_newton_euler(revolution):
    """Joint reactions Q^C = -Phi_q^T lam (eq. 7) against Newton-Euler on each body."""
    c, system = reference(), revolution["system"]
    cr, rod, sl = system.slice("crank"), system.slice("rod"), system.slice("slider")
    scale = max(abs(cf.newton_euler(c, th)["crank_from_ground"]) for th in np.linspace(0, 2 * np.pi, 64))
    for k in range(0, len(revolution["t"]), 250):
        q, lam, theta = revolution["q"][k], revolution["lam"][k], c.omega * revolution["t"][k]
        ne = cf.newton_euler(c, theta)
        react = system.reactions(q, lam)
        f_b, f_o, f_a = ne["slider_from_rod"], ne["crank_from_ground"], ne["rod_from_crank"]
        pin = c.r * np.exp(1j * theta)                              # crank pin A
        z1, z2, _ = cf.centres(c, theta)

        def moment(arm: complex, force: complex) -> float:           # (arm x force)_z
            return (np.conj(arm) * force).imag
        expected = [
            ("rod_slider", sl, (f_b.real, f_b.imag, 0.0)),
            ("slider_ground", sl, (0.0, ne["guide_normal"], 0.0)),
            ("ground_crank", cr, (f_o.real, f_o.imag, moment(-z1, f_o))),
            ("crank_rod", rod, (f_a.real, f_a.imag, moment(pin - z2, f_a))),
            ("crank_rod", cr, (-f_a.real, -f_a.imag, moment(pin - z1, -f_a))),
        ]
        for joint, body, want in expected:
            got = react[joint][body]
            assert np.allclose(got, want, rtol=0, atol=1e-6 * scale), (joint, k, got, want)
        # physical identity: the slider does not move in y, so its reactions cancel in y
        y_sum = react["rod_slider"][sl][1] + react["slider_ground"][sl][1]
        assert abs(y_sum) < 1e-9 * scale


# --------------------------------------------------------------------------- assembly and velocities
def slider_crank_exact(theta: float) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form q and qd of the ideal slider-crank at crank angle theta."""
    c = reference()
    z1, z2, z3 = cf.centres(c, theta)
    v1, v2, v3 = cf.velocities(c, theta)
    phi = cf.rod_angle(c, theta)
    phid, _ = cf.rod_rates(c, theta)
    q = np.array([z1.real, z1.imag, theta, z2.real, z2.imag, phi, z3.real, z3.imag, 0.0])
    qd = np.array([*v1, c.omega, *v2, phid, *v3, 0.0])
    return q, qd


def test_assemble_converges_from_perturbed_guess():
    system = System(build(PARAMS, "ideal"))
    theta = 0.7
    t = theta / PARAMS.omega
    q_exact, qd_exact = slider_crank_exact(theta)
    rng = np.random.default_rng(1)
    guess = q_exact + 2e-3 * rng.standard_normal(system.n)
    q = system.assemble(guess, t)
    assert np.max(np.abs(system.phi(q, t))) <= 1e-12
    assert np.max(np.abs(q - q_exact)) < 1e-11
    qd = system.velocities(q, t)
    assert np.max(np.abs(system.jacobian(q, t) @ qd + system.phi_t(t))) < 1e-12     # eq. (4)
    assert np.max(np.abs(qd - qd_exact)) < 1e-10


def test_assemble_and_velocities_underdetermined_bearing_model():
    """The bearing model has 2 free relative DOF: minimum-norm Newton and velocity steps."""
    system = System(build(PARAMS, "bearing"))
    assert (system.n, system.m) == (9, 7)
    theta = 2.0
    t = theta / PARAMS.omega
    q_exact, qd_exact = slider_crank_exact(theta)
    rng = np.random.default_rng(2)
    guess = q_exact + 1e-3 * rng.standard_normal(system.n)
    q = system.assemble(guess, t)
    assert np.max(np.abs(system.phi(q, t))) <= 1e-12
    assert np.max(np.abs(q - q_exact)) < 1e-2                     # stays near the guess
    qd_guess = qd_exact + 0.1 * rng.standard_normal(system.n)
    qd = system.velocities(q, t, qd_guess)
    J = system.jacobian(q, t)
    assert np.max(np.abs(J @ qd + system.phi_t(t))) < 1e-12       # eq. (4)
    # minimum-norm correction: the change lies in the row space of J
    dq = qd - qd_guess
    projector = J.T @ np.linalg.solve(J @ J.T, J)
    assert np.allclose(projector @ dq, dq, atol=1e-12)
    # the paper's start: the ideal velocities satisfy the bearing model's constraints too
    q0, qd0 = initial_state(system, PARAMS)
    assert np.max(np.abs(system.phi(q0, 0.0))) < 1e-15
    assert np.max(np.abs(system.jacobian(q0) @ qd0 + system.phi_t(0.0))) < 1e-12
    housing, journal = system.model.bearings[0].housing, system.model.bearings[0].journal
    assert np.allclose(system.point_position(q0, housing), system.point_position(q0, journal), atol=1e-15)
    assert np.allclose(system.point_velocity(q0, qd0, housing), system.point_velocity(q0, qd0, journal),
                       atol=1e-12)


# --------------------------------------------------------------------------- derivatives of a general model
def general_model() -> Model:
    """Three bodies with offsets, a translational joint between two moving bodies,
    an inclined axis, a non-zero locked angle, and a driver."""
    return Model(
        bodies=(Body("a", 1.0, 0.1), Body("b", 2.0, 0.2), Body("c", 0.5, 0.05)),
        joints=(Revolute("ga", Point(GROUND, (0.1, -0.2)), Point("a", (-0.3, 0.05))),
                Translational("ab", Point("a", (0.2, 0.1)), Point("b", (-0.05, 0.02)), axis=(0.6, 0.8),
                              angle0=0.3),
                Revolute("bc", Point("b", (0.1, 0.0)), Point("c", (0.0, -0.15))),
                AngleDriver("drive_c", "c", omega=3.0, theta0=0.2)),
    )


def test_jacobian_and_gamma_against_finite_differences():
    system = System(general_model())
    rng = np.random.default_rng(3)
    q, qd, t = rng.standard_normal(system.n), rng.standard_normal(system.n), 0.37
    eps = 1e-6
    J_fd = np.column_stack([(system.phi(q + eps * e, t) - system.phi(q - eps * e, t)) / (2 * eps)
                            for e in np.eye(system.n)])
    assert np.allclose(system.jacobian(q, t), J_fd, atol=1e-8)
    phi_t_fd = (system.phi(q, t + eps) - system.phi(q, t - eps)) / (2 * eps)
    assert np.allclose(system.phi_t(t), phi_t_fd, atol=1e-8)
    # eq. (5) with Phi_qt = Phi_tt = 0: gamma = -d/ds [Phi_q(q + s qd) qd] at s = 0
    dJqd = (system.jacobian(q + eps * qd, t) @ qd - system.jacobian(q - eps * qd, t) @ qd) / (2 * eps)
    assert np.allclose(system.gamma(q, qd, t), -dJqd, atol=1e-7)


def test_translational_model_equations():
    """Translational row definitions checked by hand: n . (r_j - r_i) and theta_j - theta_i - angle0."""
    system = System(general_model())
    rng = np.random.default_rng(4)
    q = rng.standard_normal(system.n)
    joint = system.model.joint("ab")
    d = system.point_position(q, joint.j) - system.point_position(q, joint.i)
    th_a = q[system.slice("a")][2]
    axis = np.array(joint.axis) / np.linalg.norm(joint.axis)
    n_global = np.array([[math.cos(th_a), -math.sin(th_a)], [math.sin(th_a), math.cos(th_a)]]) @ \
        np.array([-axis[1], axis[0]])
    phi = system.phi(q, 0.0)[system.rows("ab")]
    assert phi[0] == pytest.approx(n_global @ d, abs=1e-14)
    assert phi[1] == pytest.approx(q[system.slice("b")][2] - th_a - 0.3, abs=1e-14)


# --------------------------------------------------------------------------- simple closed forms
def test_free_body_falls_with_g():
    model = Model(bodies=(Body("ball", 2.0, 0.3),), gravity=(0.0, -G))
    system = System(model)
    assert system.m == 0
    q0, qd0 = np.array([1.0, 2.0, 0.3]), np.array([0.5, 3.0, 2.0])
    y, h, steps = np.concatenate((q0, qd0)), 1e-3, 1000
    f = state_derivative(system)
    for k in range(steps):
        y = rk4_step(f, k * h, y, h)
    t = steps * h
    expected = [1.0 + 0.5 * t, 2.0 + 3.0 * t - 0.5 * G * t * t, 0.3 + 2.0 * t, 0.5, 3.0 - G * t, 2.0]
    assert np.allclose(y, expected, rtol=0, atol=1e-12)


def test_block_on_frictionless_incline():
    """A block on an inclined guide slides with g sin(a); the guide pushes with m g cos(a)."""
    a, m = 0.5, 1.7
    model = Model(bodies=(Body("block", m, 0.02),),
                  joints=(Translational("guide", Point(GROUND, (0.1, 0.2)), Point("block", (0.05, -0.02)),
                                        axis=(math.cos(a), math.sin(a)), angle0=0.4),),
                  gravity=(0.0, -G))
    system = System(model)
    q = system.assemble(np.array([0.2, 0.2, 0.4]), 0.0)
    qd = system.velocities(q, 0.0, np.array([1.0, 0.0, 0.0]))
    qdd, lam = system.accelerations(q, qd, 0.0, system.applied_forces(q, qd, 0.0))
    along = np.array([math.cos(a), math.sin(a)])
    assert np.allclose(qdd[:2], -G * math.sin(a) * along, atol=1e-12)
    assert abs(qdd[2]) < 1e-12
    normal = np.array([-math.sin(a), math.cos(a)])
    force = system.reactions(q, lam)["guide"]
    assert np.allclose(force[:2], m * G * math.cos(a) * normal, atol=1e-12)


def test_baumgarte_error_decays_critically_damped():
    """With an initial driver error delta, Phi'' + 2 alpha Phi' + beta^2 Phi = 0, so for
    alpha = beta: Phi(t) = delta (1 + beta t) exp(-beta t)."""
    beta, omega, delta = 100.0, 5.0, 1e-3
    system = System(Model(bodies=(Body("wheel", 1.0, 0.1),),
                          joints=(AngleDriver("drive", "wheel", omega=omega),)), alpha=beta, beta=beta)
    y, h = np.array([0.0, 0.0, delta, 0.0, 0.0, omega]), 1e-4
    f = state_derivative(system)
    for k in range(300):
        y = rk4_step(f, k * h, y, h)
        t = (k + 1) * h
        exact = delta * (1.0 + beta * t) * math.exp(-beta * t)
        assert system.phi(y[:3], t)[0] == pytest.approx(exact, abs=1e-9 * delta)


def test_point_force_and_kinematics_by_hand():
    system = System(Model(bodies=(Body("bar", 1.0, 0.1),)))
    q = np.array([1.0, 1.0, math.pi / 2])
    qd = np.array([0.2, -0.1, 3.0])
    p = Point("bar", (1.0, 0.0))
    assert np.allclose(system.point_position(q, p), [1.0, 2.0], atol=1e-15)
    assert np.allclose(system.point_velocity(q, qd, p), [0.2 - 3.0, -0.1], atol=1e-15)
    assert np.allclose(system.point_force(q, p, np.array([3.0, 0.0])), [3.0, 0.0, -3.0], atol=1e-15)
    assert np.allclose(system.point_force(q, p, np.array([0.0, 2.0]), at=np.array([3.0, 1.0])),
                       [0.0, 2.0, 4.0], atol=1e-15)
    assert np.allclose(system.point_force(q, Point(GROUND, (0.0, 0.0)), np.array([1.0, 1.0])), 0.0)
    assert system.kinetic_energy(qd) == pytest.approx(0.5 * (0.04 + 0.01) + 0.5 * 0.1 * 9.0)
