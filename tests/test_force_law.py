"""The ball-bearing force law (eq. 16-19, 24-32) against closed forms, symmetries and finite differences.

These tests call ``fmu_bearing`` in-process; tests/test_fmu.py checks the built FMU against it.
"""
import math

import numpy as np
import pytest

from fmu_bearing import hertz
from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import (DAMPING_CONSTANT, DAMPING_NONE, DAMPING_OIL_FILM, BearingParameterError,
                                    BearingParameters, validate)

TABLE2 = BearingParameters()
HALF = TABLE2.radial_clearance / 2            # P_d / 2 = 10 um


def rot(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def run(b, e, v, cage, w_i=0.0, w_o=0.0):
    loads = [float("nan")] * b.n_balls
    r = b.evaluate(e[0], e[1], v[0], v[1], cage, w_i, w_o, loads)
    F = np.array([r.F_x, r.F_y])
    K = np.array([[r.k_xx, r.k_xy], [r.k_xy, r.k_yy]])
    C = np.array([[r.c_xx, r.c_xy], [r.c_xy, r.c_yy]])
    return F, K, C, np.array(loads), r


def random_loaded_state(rng, e_max=4e-5, v_scale=0.05):
    a = rng.uniform(0, 2 * math.pi)
    e = rng.uniform(HALF * 1.05, e_max) * np.array([math.cos(a), math.sin(a)])
    return e, rng.normal(0.0, v_scale, 2), rng.uniform(-10, 10)


# --- a single loaded ball ----------------------------------------------------------------------

@pytest.mark.parametrize("damping_model, C", [(DAMPING_NONE, 0.0), (DAMPING_CONSTANT, 50.0),
                                              (DAMPING_CONSTANT, 400.0)])
@pytest.mark.parametrize("cage", [0.0, 0.3, -2.0, 7.5])
def test_single_loaded_ball_closed_form(damping_model, C, cage):
    b = BallBearing(TABLE2.replace(damping_model=damping_model, damping_coefficient=C))
    K = b.stiffness
    # e along ball 1; the neighbours at +-45 deg see e cos 45 - P_d/2 <= 0 as long as e <= P_d/2 / cos 45 = 14.1 um
    delta = 3e-6
    e_mag = HALF + delta
    assert e_mag * math.cos(math.pi / 4) < HALF
    u = np.array([math.cos(cage), math.sin(cage)])
    t = np.array([-u[1], u[0]])
    v_r = 2e-3
    v = v_r * u + 7e-3 * t                       # the tangential part carries no force
    F, Kt, Ct, loads, r = run(b, e_mag * u, v, cage)
    W = K * delta ** 1.5 + C * v_r               # eq. (18)
    np.testing.assert_allclose(F, W * u, rtol=1e-12, atol=1e-12 * W)
    assert loads[0] == pytest.approx(W, rel=1e-12)
    assert np.all(loads[1:] == 0.0)
    assert r.loaded_balls == 1 and r.max_ball_load == pytest.approx(W, rel=1e-12)
    np.testing.assert_allclose(Kt, 1.5 * K * math.sqrt(delta) * np.outer(u, u), rtol=1e-12, atol=1e-3)
    np.testing.assert_allclose(Ct, C * np.outer(u, u), rtol=1e-12, atol=1e-12)


def test_three_loaded_balls_closed_form():
    """8 balls, cage 0, e = (30 um, 0): balls at 0 and +-45 deg loaded, F_y = 0 by symmetry."""
    b = BallBearing(TABLE2.replace(damping_model=DAMPING_NONE))
    K, eps, s = b.stiffness, 30e-6, math.sqrt(0.5)
    d0, d45 = eps - HALF, eps * s - HALF
    F, Kt, _, loads, r = run(b, (eps, 0.0), (0.0, 0.0), 0.0)
    assert F[0] == pytest.approx(K * d0 ** 1.5 + 2 * K * d45 ** 1.5 * s, rel=1e-12)
    assert abs(F[1]) < 1e-9 * F[0]
    assert r.loaded_balls == 3
    np.testing.assert_allclose(loads[[0, 1, 7]], [K * d0 ** 1.5, K * d45 ** 1.5, K * d45 ** 1.5], rtol=1e-12)
    assert np.all(loads[2:7] == 0.0)
    assert Kt[0, 0] == pytest.approx(1.5 * K * (d0 ** 0.5 + 2 * d45 ** 0.5 * 0.5), rel=1e-12)
    assert Kt[1, 1] == pytest.approx(1.5 * K * 2 * d45 ** 0.5 * 0.5, rel=1e-12)
    assert abs(Kt[0, 1]) < 1e-9 * Kt[0, 0]


def test_journal_pushed_in_plus_x_pushes_housing_in_plus_x():
    F, *_ = run(BallBearing(TABLE2), (2e-5, 0.0), (0.0, 0.0), 0.0)
    assert F[0] > 0  # force on the housing (eq. 20); the journal receives -F


# --- clearance, clamp ----------------------------------------------------------------------------

@pytest.mark.parametrize("damping_model", [DAMPING_NONE, DAMPING_CONSTANT, DAMPING_OIL_FILM])
def test_zero_force_inside_the_clearance(damping_model):
    b = BallBearing(TABLE2.replace(damping_model=damping_model))
    rng = np.random.default_rng(1)
    for _ in range(500):
        a = rng.uniform(0, 2 * math.pi)
        e = HALF * (1 - 1e-9) * math.sqrt(rng.uniform()) * np.array([math.cos(a), math.sin(a)])
        F, Kt, Ct, loads, r = run(b, e, rng.normal(0, 10.0, 2), rng.uniform(-50, 50), *rng.normal(0, 300, 2))
        assert np.all(F == 0) and np.all(Kt == 0) and np.all(Ct == 0) and np.all(loads == 0)
        assert r.loaded_balls == 0 and r.max_ball_load == 0


def test_no_tension_clamp():
    """A loaded ball whose damping term would pull carries 0 N and adds nothing to K and C."""
    C = 200.0
    b = BallBearing(TABLE2.replace(damping_coefficient=C))
    cage, delta = 1.1, 2e-6
    u = np.array([math.cos(cage), math.sin(cage)])
    W = b.stiffness * delta ** 1.5
    # separating fast enough: K delta^1.5 + C v_r < 0
    F, Kt, Ct, loads, r = run(b, (HALF + delta) * u, -2.0 * W / C * u, cage)
    assert np.all(F == 0) and np.all(loads == 0) and r.loaded_balls == 0 and r.max_ball_load == 0
    assert np.all(Kt == 0) and np.all(Ct == 0)
    # separating slowly: still pushing, with half the Hertz force
    F, Kt, Ct, loads, r = run(b, (HALF + delta) * u, -0.5 * W / C * u, cage)
    np.testing.assert_allclose(F, 0.5 * W * u, rtol=1e-9, atol=1e-12)
    assert r.loaded_balls == 1


# --- symmetries --------------------------------------------------------------------------------

@pytest.mark.parametrize("damping_model", [DAMPING_CONSTANT, DAMPING_OIL_FILM])
def test_rotating_e_v_and_cage_rotates_the_force(damping_model):
    b = BallBearing(TABLE2.replace(damping_model=damping_model))
    rng = np.random.default_rng(2)
    for _ in range(200):
        e, v, cage = random_loaded_state(rng)
        alpha = rng.uniform(-4 * math.pi, 4 * math.pi)
        R = rot(alpha)
        F, Kt, Ct, loads, r = run(b, e, v, cage, 120.0, -15.0)
        F2, Kt2, Ct2, loads2, r2 = run(b, R @ e, R @ v, cage + alpha, 120.0, -15.0)
        scale = np.abs(F).max() + 1e-9
        np.testing.assert_allclose(F2, R @ F, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(Kt2, R @ Kt @ R.T, rtol=0, atol=1e-9 * (np.abs(Kt).max() + 1))
        np.testing.assert_allclose(Ct2, R @ Ct @ R.T, rtol=0, atol=1e-9 * (np.abs(Ct).max() + 1e-9))
        np.testing.assert_allclose(loads2, loads, rtol=1e-9, atol=1e-9 * scale)
        assert r2.loaded_balls == r.loaded_balls


@pytest.mark.parametrize("n_balls", [8, 11])
def test_n_fold_symmetry(n_balls):
    """Turning the cage by one ball pitch changes nothing but which ball carries which load."""
    b = BallBearing(TABLE2.replace(n_balls=n_balls))
    rng = np.random.default_rng(3)
    pitch = 2 * math.pi / n_balls
    for _ in range(100):
        e, v, cage = random_loaded_state(rng)
        F, Kt, Ct, loads, _ = run(b, e, v, cage)
        F2, Kt2, Ct2, loads2, _ = run(b, e, v, cage + pitch)
        scale = np.abs(F).max() + 1e-9
        np.testing.assert_allclose(F2, F, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(Kt2, Kt, rtol=0, atol=1e-9 * (np.abs(Kt).max() + 1))
        np.testing.assert_allclose(Ct2, Ct, rtol=0, atol=1e-9 * (np.abs(Ct).max() + 1e-9))
        np.testing.assert_allclose(loads2, np.roll(loads, -1), rtol=0, atol=1e-9 * scale)


# --- tangent matrices --------------------------------------------------------------------------

@pytest.mark.parametrize("damping_model", [DAMPING_NONE, DAMPING_CONSTANT, DAMPING_OIL_FILM])
def test_tangent_matrices_match_central_differences(damping_model):
    b = BallBearing(TABLE2.replace(damping_model=damping_model))
    rng = np.random.default_rng(4)
    w_i, w_o = 60.0, -5.0
    he, hv = 1e-11, 1e-7
    checked = 0
    while checked < 60:
        e, v, cage = random_loaded_state(rng, e_max=6e-5, v_scale=1e-3)
        deltas = [e @ (math.cos(phi), math.sin(phi)) - HALF for phi in b.ball_angles(cage)]
        if any(-1e-8 < d < 2e-7 for d in deltas):  # keep the finite differences off the kinks
            continue
        checked += 1
        _, Kt, Ct, _, _ = run(b, e, v, cage, w_i, w_o)
        Kfd, Cfd = np.zeros((2, 2)), np.zeros((2, 2))
        for j in range(2):
            d = np.zeros(2)
            d[j] = he
            Kfd[:, j] = (run(b, e + d, v, cage, w_i, w_o)[0] - run(b, e - d, v, cage, w_i, w_o)[0]) / (2 * he)
            d[j] = hv
            Cfd[:, j] = (run(b, e, v + d, cage, w_i, w_o)[0] - run(b, e, v - d, cage, w_i, w_o)[0]) / (2 * hv)
        np.testing.assert_allclose(Kt, Kfd, rtol=0, atol=2e-5 * np.abs(Kt).max())
        np.testing.assert_allclose(Ct, Cfd, rtol=0, atol=1e-6 * max(np.abs(Ct).max(), 1e-3))
        assert Kt[0, 1] == Kt[1, 0]                     # symmetric: dF_x/de_y = dF_y/de_x
        assert Kfd[0, 1] == pytest.approx(Kfd[1, 0], rel=1e-4, abs=1e-4 * np.abs(Kt).max())


# --- cage kinematics ---------------------------------------------------------------------------

def test_cage_advances_with_eq16():
    b = BallBearing(TABLE2)
    # omega_m = (omega_i d_i + omega_o d_o) / (d_i + d_o) with d_i = 29.2 mm, d_o = 46.6 mm (Table 2)
    w_i, w_o, dt = 100.0, -20.0, 1e-3
    expected = 0.25 + dt * (100.0 * 29.2 - 20.0 * 46.6) / (29.2 + 46.6)
    assert b.advance_cage(0.25, w_i, w_o, dt) == pytest.approx(expected, rel=1e-13)
    assert b.advance_cage(0.25, 7.0, 7.0, dt) == pytest.approx(0.25 + 7e-3, rel=1e-13)  # rigid rotation
    angles = b.ball_angles(0.25)
    np.testing.assert_allclose(np.diff(angles), 2 * math.pi / 8, rtol=1e-13)


# --- Hertz stiffness (eq. 24-28) ---------------------------------------------------------------

def table2_contacts(f=0.52):
    return hertz.raceway_contacts(TABLE2.ball_diameter, TABLE2.pitch_diameter, f, f)


def test_table2_stiffness_is_about_9p7e9():
    K = hertz.ball_stiffness(TABLE2.ball_diameter, TABLE2.pitch_diameter, TABLE2.youngs_modulus,
                             TABLE2.poisson_ratio, 0.52, 0.52)
    assert abs(K / 9.7e9 - 1) < 0.01          # the "about 9.7e9 N/m^1.5"
    assert abs(K / 9.68e9 - 1) < 0.002
    assert BallBearing(TABLE2).stiffness == pytest.approx(K, rel=1e-14)


def test_eq26_and_hamrock_brewe_agree_with_exact_hertz():
    E, nu = TABLE2.youngs_modulus, TABLE2.poisson_ratio
    contacts = table2_contacts()
    exact = [hertz.contact_stiffness(c.sum_rho, hertz.dimensionless_deflection(c.F_rho), E, nu) for c in contacts]
    eq26 = [hertz.stiffness_eq26(c.sum_rho, hertz.dimensionless_deflection(c.F_rho)) for c in contacts]
    hb = [hertz.stiffness_hamrock_brewe(c, E, nu) for c in contacts]
    K = hertz.series_stiffness(*exact)
    for approx in (eq26, hb):
        for a, x in zip(approx, exact):
            assert abs(a / x - 1) < 0.025
        assert abs(hertz.series_stiffness(*approx) / K - 1) < 0.025


def test_series_stiffness_closed_form():
    # equal contacts: delta = 2 (W/K_p)^(2/3) => K = K_p / 2^1.5
    assert hertz.series_stiffness(3e10, 3e10) == pytest.approx(3e10 / 2 ** 1.5, rel=1e-14)


def test_sphere_on_flat_limit():
    """F(rho) -> 0 is a circular contact: delta* -> 1 and K_p -> (4/3) E* sqrt(R) (sphere of radius R on a flat)."""
    assert hertz.dimensionless_deflection(1e-7) == pytest.approx(1.0, abs=1e-5)
    D, E, nu = 8.7e-3, 207e9, 0.3
    e_star = E / (2 * (1 - nu ** 2))            # both bodies steel
    K = hertz.contact_stiffness(4.0 / D, 1.0, E, nu)  # ball on a flat: sum rho = 2/D + 2/D
    assert K == pytest.approx(4.0 / 3.0 * e_star * math.sqrt(D / 2), rel=1e-13)


@pytest.mark.parametrize("F_rho", [0.3, 0.6, 0.9, 0.95])
def test_exact_ellipticity_against_hamrock_brewe(F_rho):
    # Hamrock-Brewe: kappa ~ 1.0339 (R_y/R_x)^0.636 with R_y/R_x = (1 + F)/(1 - F) for a point contact;
    # their fit holds to a few per cent up to R_y/R_x ~ 40 (F = 0.95), which covers ball bearings (F ~ 0.9-0.94)
    kappa = hertz.ellipticity(F_rho)
    assert kappa == pytest.approx(1.0339 * ((1 + F_rho) / (1 - F_rho)) ** 0.636, rel=0.03)


# --- parameter validation ----------------------------------------------------------------------

INVALID = [
    ({"n_balls": 2}, None, "n_balls"),
    ({"n_balls": 21}, 20, "n_balls"),
    ({"n_balls": 14}, None, "n_balls"),                 # 37.9 mm sin(pi/14) = 8.4 mm < D = 8.7 mm
    ({"inner_race_diameter": 30.0e-3}, None, "inner_race_diameter"),
    ({"outer_race_diameter": 45.5e-3}, None, "outer_race_diameter"),
    ({"radial_clearance": -0.1e-3}, None, "radial_clearance"),   # preload beyond -1 % D = -87 um
    ({"reliability_factor": 0.0}, None, "reliability_factor"),
    ({"reliability_factor": 1.5}, None, "reliability_factor"),
    ({"youngs_modulus": 0.0}, None, "youngs_modulus"),
    ({"youngs_modulus": -2e11}, None, "youngs_modulus"),
    ({"poisson_ratio": 0.0}, None, "poisson_ratio"),
    ({"poisson_ratio": 0.5}, None, "poisson_ratio"),
    ({"poisson_ratio": -0.1}, None, "poisson_ratio"),
    ({"poisson_ratio": 0.7}, None, "poisson_ratio"),
    ({"inner_groove_conformity": 0.5}, None, "inner_groove_conformity"),
    ({"outer_groove_conformity": 0.45}, None, "outer_groove_conformity"),
    ({"damping_coefficient": -1.0}, None, "damping_coefficient"),
    ({"oil_viscosity": -0.01}, None, "oil_viscosity"),
    ({"pressure_viscosity_coefficient": -1e-8}, None, "pressure_viscosity_coefficient"),
    ({"ball_diameter": float("nan")}, None, "ball_diameter"),
]


@pytest.mark.parametrize("changes, capacity, name", INVALID, ids=[f"{n}={c[n]!r}" for c, _, n in INVALID])
def test_invalid_parameter_raises_naming_it(changes, capacity, name):
    p = TABLE2.replace(**changes)
    for check in (lambda: validate(p, capacity), lambda: BallBearing(p, capacity)):
        with pytest.raises(BearingParameterError) as err:
            check()
        assert err.value.name == name
        assert name in str(err.value) and repr(changes[name]) in str(err.value)


def test_valid_parameters_pass():
    validate(TABLE2, 8)
    BallBearing(TABLE2.replace(n_balls=13), 20)             # 37.9 mm sin(pi/13) = 9.1 mm > D
    BallBearing(TABLE2.replace(n_balls=20, allow_ball_overlap=True), 20)   # the paper's 20-ball study


# --- a ball's deflection and its rate (eq. 16-18), the one home of the onset location's kinematics -------------

def test_deflection_is_the_load_laws_bracket_and_its_rate_is_its_time_derivative():
    """delta_r = e . u_r - P_d/2: at phi = 0 and pi/2 the eccentricity's component less the half clearance; a ball
    is loaded by ``evaluate`` exactly where it is positive; the rate equals a central difference of the deflection
    along e + v t at the ball angle phi + omega t (an independent formulation of d/dt)."""
    b = BallBearing(TABLE2)
    assert b.deflection(3e-5, -7e-6, 0.0) == pytest.approx(3e-5 - HALF, rel=1e-15)
    assert b.deflection(3e-5, -7e-6, math.pi / 2) == pytest.approx(-7e-6 - HALF, abs=1e-20)
    rng = np.random.default_rng(5)
    for _ in range(20):
        e, v, cage = random_loaded_state(rng)
        _, _, _, loads, _ = run(b, e, np.zeros(2), cage)
        for r, phi in enumerate(b.ball_angles(cage)):
            assert (loads[r] > 0.0) == (b.deflection(e[0], e[1], phi) > 0.0)
        omega, phi, dt = rng.uniform(-300.0, 300.0), rng.uniform(0, 2 * math.pi), 1e-7
        ahead = b.deflection(e[0] + v[0] * dt, e[1] + v[1] * dt, phi + omega * dt)
        back = b.deflection(e[0] - v[0] * dt, e[1] - v[1] * dt, phi - omega * dt)
        rate = b.deflection_rate(e[0], e[1], v[0], v[1], phi, omega)
        assert rate == pytest.approx((ahead - back) / (2 * dt), rel=1e-6, abs=1e-12)
