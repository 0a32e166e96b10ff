"""Bearing rating life (fmu_bearing.life, issue 16): ISO 281 / ISO/TS 16281 by hand, the catalogue life,
life against clearance (quasi-static), preload in the force law, and the life outputs of the built FMU."""
from __future__ import annotations

import math

import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from scipy.optimize import brentq

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.life import LifeAccumulator, LifeInputError, LoadRatings, f_c_factor
from fmu_bearing.parameters import BearingParameterError, BearingParameters

TABLE2 = BearingParameters()
REL = 1e-9


# --- the formulas by hand --------------------------------------------------------------------------

def hand_ratings(D_mm=8.7, dm_mm=37.9, Z=8, fi=0.52, fe=0.52):
    """C_r, Q_ci, Q_ce written out from ISO 281 clause 5.1, Table 2 (rows 0.22 and 0.23) and ISO/TS 16281."""
    g = D_mm / dm_mm                                        # 0.2296: between the rows 0.22 and 0.23
    assert 0.22 < g < 0.23
    fc = 59.6 + (g - 0.22) / 0.01 * (59.3 - 59.6)          # ISO 281 Table 2, linear interpolation
    C_r = 1.3 * fc * 1.0 ** 0.7 * Z ** (2 / 3) * D_mm ** 1.8
    k = 1.3 * 98.1 * g ** 0.3 * D_mm ** 1.8 / Z ** (1 / 3)
    Q_ci = k * (2 * fi / (2 * fi - 1)) ** 0.41 * (1 - g) ** 1.39 / (1 + g) ** (1 / 3)
    Q_ce = k * (2 * fe / (2 * fe - 1)) ** 0.41 * (1 + g) ** 1.39 / (1 - g) ** (1 / 3)
    return C_r, Q_ci, Q_ce


def test_ratings_equal_the_hand_computation():
    r = LoadRatings.of_bearing(TABLE2)
    C_r, Q_ci, Q_ce = hand_ratings()
    assert r.C_r == pytest.approx(C_r, rel=REL)
    assert r.Q_ci == pytest.approx(Q_ci, rel=REL)
    assert r.Q_ce == pytest.approx(Q_ce, rel=REL)
    # a bearing of the SKF/FAG 6205 size class: C_r of 14-15 kN
    assert 14e3 < r.C_r < 16e3


def test_f_c_table_rows_and_range():
    assert f_c_factor(0.01) == pytest.approx(29.1)
    assert f_c_factor(0.19) == pytest.approx(60.0)
    assert f_c_factor(0.40) == pytest.approx(48.4)
    assert f_c_factor(0.105) == pytest.approx(0.5 * (55.5 + 56.6))
    with pytest.raises(LifeInputError, match="Table 2"):
        f_c_factor(0.45)


#: a fixed load distribution over the 8 balls [N] (ball 1 at the load line)
LOADS = [1200.0, 800.0, 150.0, 0.0, 0.0, 0.0, 150.0, 800.0]


def cubic(q):
    return (sum(x ** 3 for x in q) / len(q)) ** (1 / 3)


def power_10_3(q):
    return (sum(x ** (10 / 3) for x in q) / len(q)) ** 0.3


@pytest.mark.parametrize("rotating", ["outer", "inner"])
def test_life_of_a_fixed_load_distribution_equals_the_hand_computation(rotating):
    _, Q_ci, Q_ce = hand_ratings()
    acc = LifeAccumulator(LoadRatings.of_bearing(TABLE2), reliability_factor=0.64)
    steps = [(125.0, 1e-3), (60.0, 2e-3), (200.0, 0.5e-3)]     # (speed of the rotating ring [rad/s], dt [s])
    for w, dt in steps:
        acc.add(LOADS, 0.0 if rotating == "outer" else w, w if rotating == "outer" else 0.0, dt)
    # rotating ring: cubic mean over the balls; stationary ring: (10/3)-power mean (ISO/TS 16281)
    Q_ei = cubic(LOADS) if rotating == "inner" else power_10_3(LOADS)
    Q_ee = power_10_3(LOADS) if rotating == "inner" else cubic(LOADS)
    L10r = 0.64 * ((Q_ci / Q_ei) ** (-10 / 3) + (Q_ce / Q_ee) ** (-10 / 3)) ** (-9 / 10)
    revolutions = sum(w * dt for w, dt in steps) / (2 * math.pi)
    rpm = revolutions / sum(dt for _, dt in steps) * 60
    assert acc.equivalent_load_inner == pytest.approx(Q_ei, rel=REL)
    assert acc.equivalent_load_outer == pytest.approx(Q_ee, rel=REL)
    assert acc.life_revolutions == pytest.approx(L10r, rel=REL)
    assert acc.life_hours == pytest.approx(L10r * 1e6 / (60 * rpm), rel=REL)


def test_time_average_is_the_revolution_weighted_cubic_mean():
    """Two load levels: Palmgren-Miner with exponent 3, weighted by the relative revolutions."""
    acc = LifeAccumulator(LoadRatings.of_bearing(TABLE2))
    half = [0.5 * q for q in LOADS]
    acc.add(LOADS, 0.0, 100.0, 1e-3)       # 0.1 rad of relative rotation
    acc.add(half, 0.0, 300.0, 1e-3)        # 0.3 rad: three times the weight
    q_rot = ((cubic(LOADS) ** 3 * 0.1 + cubic(half) ** 3 * 0.3) / 0.4) ** (1 / 3)
    q_stat = ((power_10_3(LOADS) ** 3 * 0.1 + power_10_3(half) ** 3 * 0.3) / 0.4) ** (1 / 3)
    assert acc.equivalent_load_outer == pytest.approx(q_rot, rel=REL)
    assert acc.equivalent_load_inner == pytest.approx(q_stat, rel=REL)


def test_life_is_infinite_before_any_ball_is_loaded():
    acc = LifeAccumulator(LoadRatings.of_bearing(TABLE2))
    assert acc.life_revolutions == math.inf and acc.life_hours == math.inf
    acc.add([0.0] * 8, 0.0, 100.0, 1e-3)
    assert acc.life_hours == math.inf and acc.equivalent_load_inner == 0.0
    acc.add(LOADS, 0.0, 100.0, 1e-3)
    assert math.isfinite(acc.life_hours)


def test_state_round_trip_and_invalid_state():
    acc = LifeAccumulator(LoadRatings.of_bearing(TABLE2))
    acc.add(LOADS, 0.0, 100.0, 1e-3)
    saved, life = acc.state(), acc.life_hours
    acc.add(LOADS, 0.0, 100.0, 5e-3)
    acc.restore(saved)
    assert acc.life_hours == life
    with pytest.raises(LifeInputError):
        acc.restore([1.0, -2.0, 3.0, 4.0])
    assert acc.state() == saved                       # nothing assigned from a bad state


# --- quasi-static life against the catalogue and against clearance -------------------------------

def quasi_static_life(radial_clearance: float, load: float, params: BearingParameters = TABLE2,
                      positions: int = 40, rotating: str = "inner") -> float:
    """L10r [Mrev] of a constant radial load [N] along x with the ``rotating`` ring turning: for cage positions
    over one ball spacing, solve F_x(e) = load for the static eccentricity with the force law, and accumulate."""
    speeds = (100.0, 0.0) if rotating == "inner" else (0.0, 100.0)
    p = params.replace(radial_clearance=radial_clearance, damping_model=0)
    bearing = BallBearing(p)
    acc = LifeAccumulator(LoadRatings.of_bearing(p))
    loads = [0.0] * p.n_balls
    for k in range(positions):
        cage = 2 * math.pi / p.n_balls * (k + 0.5) / positions
        e = brentq(lambda x: bearing.evaluate(x, 0.0, 0.0, 0.0, cage).F_x - load, -1e-4, 1e-3, xtol=1e-15)
        bearing.evaluate(e, 0.0, 0.0, 0.0, cage, loads=loads)
        acc.add(loads, *speeds, 1e-3)
    return acc.life_revolutions


@pytest.mark.parametrize("conformities, load_tolerance", [((0.52, 0.52), 0.05), ((0.52, 0.53), 0.035)])
def test_zero_clearance_life_is_near_the_catalogue_life(conformities, load_tolerance):
    """L10r against ISO 281's (C_r/P)^3 at zero clearance, inner ring rotating (the basis of C_r): the same
    life to a few percent in load. Measured: L10r/L10 = 1.14 (4.5 % in load) with the default conformities
    0.52/0.52, 1.09 (2.9 %) with ISO/TR 1281-1's 0.52/0.53; the differences are explained in
    docs/bearing-life.md.
    """
    p = TABLE2.replace(inner_groove_conformity=conformities[0], outer_groove_conformity=conformities[1])
    C_r = LoadRatings.of_bearing(p).C_r
    for load in (500.0, 2000.0):
        ratio = quasi_static_life(0.0, load, p) / (C_r / load) ** 3
        assert 1.0 < ratio ** (1 / 3) < 1.0 + load_tolerance, ratio


@pytest.mark.parametrize("load, rotating", [(500.0, "inner"), (2000.0, "inner"), (1000.0, "outer")])
def test_life_peaks_at_a_small_preload_and_falls_with_clearance(load, rotating):
    clearances = [c * 1e-6 for c in (-40, -20, -12, -8, -5, -2, 0, 5, 10, 20, 40, 60)]
    lives = [quasi_static_life(c, load, rotating=rotating) for c in clearances]
    best = clearances[lives.index(max(lives))]
    assert -20e-6 < best < 0.0                                # the optimum is a small preload
    above = [life for c, life in zip(clearances, lives) if c >= best]
    assert all(a > b for a, b in zip(above, above[1:]))       # monotonic fall above the optimum
    assert lives[0] < 0.5 * lives[clearances.index(0.0)]      # heavy preload: steep fall


# --- preload in the force law -----------------------------------------------------------------------

PRELOAD = TABLE2.replace(radial_clearance=-10e-6, damping_model=0)


def test_preload_loads_every_ball_at_zero_eccentricity_with_zero_resultant():
    b = BallBearing(PRELOAD)
    loads = [0.0] * 8
    r = b.evaluate(0.0, 0.0, 0.0, 0.0, 0.3, loads=loads)
    q0 = b.stiffness * 5e-6 ** 1.5                            # K (|P_d|/2)^1.5 on every ball
    assert r.loaded_balls == 8 and loads == pytest.approx([q0] * 8, rel=1e-12)
    assert abs(r.F_x) < 1e-9 * q0 and abs(r.F_y) < 1e-9 * q0
    k = 8 / 2 * 1.5 * b.stiffness * 5e-6 ** 0.5               # sum of 1.5 K sqrt(delta) cos^2 = N/2 ...
    assert r.k_xx == pytest.approx(k, rel=1e-12) and r.k_yy == pytest.approx(k, rel=1e-12)
    assert abs(r.k_xy) < 1e-9 * k


def test_preload_tangent_stiffness_matches_finite_differences():
    b = BallBearing(PRELOAD.replace(damping_model=1))
    e, h = (2e-6, -1.5e-6), 1e-11
    r = b.evaluate(*e, 0.01, 0.0, 0.2)
    for col, (dx, dy) in enumerate(((h, 0.0), (0.0, h))):
        plus = b.evaluate(e[0] + dx, e[1] + dy, 0.01, 0.0, 0.2)
        minus = b.evaluate(e[0] - dx, e[1] - dy, 0.01, 0.0, 0.2)
        dfx, dfy = (plus.F_x - minus.F_x) / (2 * h), (plus.F_y - minus.F_y) / (2 * h)
        expect = (r.k_xx, r.k_xy) if col == 0 else (r.k_xy, r.k_yy)
        assert dfx == pytest.approx(expect[0], rel=1e-6) and dfy == pytest.approx(expect[1], rel=1e-6)


def test_preload_bound():
    BallBearing(TABLE2.replace(radial_clearance=-0.01 * TABLE2.ball_diameter))
    with pytest.raises(BearingParameterError, match="radial_clearance"):
        BallBearing(TABLE2.replace(radial_clearance=-0.011 * TABLE2.ball_diameter))


# --- the built FMU ----------------------------------------------------------------------------------

LIFE_OUTPUTS = ["dynamic_load_rating", "raceway_rating_inner", "raceway_rating_outer", "equivalent_load_inner",
                "equivalent_load_outer", "rating_life", "rating_life_revolutions"]


def in_process(params: BearingParameters, inputs: dict, h: float, n: int) -> LifeAccumulator:
    """The FMU's step semantics in process: advance the cage, evaluate, accumulate the end-of-step loads."""
    b = BallBearing(params)
    acc = LifeAccumulator(LoadRatings.of_bearing(params), params.reliability_factor)
    x = {**dict(e_x=0.0, e_y=0.0, v_x=0.0, v_y=0.0, omega_inner=0.0, omega_outer=0.0), **inputs}
    cage, loads = params.cage_angle_start, [0.0] * params.n_balls
    for _ in range(n):
        cage = b.advance_cage(cage, x["omega_inner"], x["omega_outer"], h)
        b.evaluate(x["e_x"], x["e_y"], x["v_x"], x["v_y"], cage, x["omega_inner"], x["omega_outer"], loads)
        acc.add(loads, x["omega_inner"], x["omega_outer"], h)
    return acc


@pytest.mark.parametrize("clearance", [20e-6, -10e-6])
def test_fmu_reports_ratings_and_life_through_fmpy(ball_bearing_fmu, clearance):
    inputs = {"e_x": 30e-6, "e_y": 5e-6, "omega_inner": 20.0, "omega_outer": 125.0}
    start = dict(inputs, radial_clearance=clearance, reliability_factor=0.64)
    h, n = 1e-4, 200
    res = simulate_fmu(str(ball_bearing_fmu), start_values=start, output=LIFE_OUTPUTS + ["loaded_balls"],
                       step_size=h, output_interval=h, stop_time=n * h)
    params = TABLE2.replace(radial_clearance=clearance, reliability_factor=0.64)
    acc = in_process(params, inputs, h, n)
    last = res[-1]
    assert last["dynamic_load_rating"] == pytest.approx(acc.ratings.C_r, rel=1e-12)
    assert last["raceway_rating_inner"] == pytest.approx(acc.ratings.Q_ci, rel=1e-12)
    assert last["raceway_rating_outer"] == pytest.approx(acc.ratings.Q_ce, rel=1e-12)
    assert last["equivalent_load_inner"] == pytest.approx(acc.equivalent_load_inner, rel=1e-9)
    assert last["equivalent_load_outer"] == pytest.approx(acc.equivalent_load_outer, rel=1e-9)
    assert last["rating_life"] == pytest.approx(acc.life_hours, rel=1e-9)
    assert last["rating_life_revolutions"] == pytest.approx(acc.life_revolutions, rel=1e-9)
    assert res[0]["rating_life"] == math.inf                      # nothing accumulated at initialisation
    assert 0 < last["rating_life"] < math.inf


def test_fmu_life_is_infinite_inside_the_clearance(ball_bearing_fmu):
    md = read_model_description(str(ball_bearing_fmu))
    var = {v.name: v for v in md.modelVariables}
    assert var["rating_life"].unit == "h" and "inf" in var["rating_life"].description
    res = simulate_fmu(str(ball_bearing_fmu), start_values={"e_x": 5e-6, "omega_outer": 125.0},
                       output=["rating_life", "equivalent_load_outer"], step_size=1e-4, stop_time=1e-2)
    assert all(math.isinf(x) for x in res["rating_life"]) and not any(res["equivalent_load_outer"])


def test_fmu_state_rolls_the_life_back(ball_bearing_fmu, tmp_path):
    md = read_model_description(str(ball_bearing_fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(ball_bearing_fmu), unzipdir=str(tmp_path)),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="life")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.setReal([vr["e_x"], vr["omega_outer"]], [30e-6, 125.0])
    s.exitInitializationMode()
    life_vrs = [vr[n] for n in ("equivalent_load_outer", "rating_life")]
    t, h = 0.0, 1e-4
    for _ in range(20):
        s.doStep(t, h)
        t += h
    state, before, t_saved = s.getFMUstate(), s.getReal(life_vrs), t
    s.setReal([vr["e_x"]], [60e-6])                     # a heavier load: shorter life
    for _ in range(20):
        s.doStep(t, h)
        t += h
    heavier = s.getReal(life_vrs)
    assert heavier[1] < before[1]
    s.setFMUstate(state)
    assert s.getReal(life_vrs) == before
    s.setReal([vr["e_x"]], [60e-6])
    t = t_saved
    for _ in range(20):
        s.doStep(t, h)
        t += h
    assert s.getReal(life_vrs) == pytest.approx(heavier, rel=1e-12)   # the redone steps give the same life
    s.freeFMUstate(state)
    s.terminate()
    s.freeInstance()
