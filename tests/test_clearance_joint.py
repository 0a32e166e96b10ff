"""The journal-in-bushing clearance joint (Lankarani-Nikravesh) and its JournalClearance FMU.

Closed forms, hysteresis and restitution, tangent matrices against finite differences, rotation
symmetry, the sphere-to-sphere stiffness by hand, and the built FMU against the in-process law.
"""
from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.special import beta

from fmu_bearing.ball_bearing import BallBearing, BearingInputError
from fmu_bearing.clearance_joint import (CLEARANCE_PARAMETER_NAMES, ClearanceJoint, ClearanceParameters,
                                         ContactState, hysteresis_factor, sphere_contact_stiffness)
from fmu_bearing.parameters import BearingParameterError, BearingParameters

ROOT = Path(__file__).resolve().parents[1]
SLAVE = ROOT / "fmu_bearing" / "slaves" / "journal_clearance_fmu.py"

JOINT = ClearanceJoint()
C = JOINT.clearance
K = JOINT.stiffness


def full_jacobian(f) -> tuple[np.ndarray, np.ndarray]:
    """dF/de (exact, from the symmetric and skew parts) and dF/dv of a ClearanceForce."""
    k = np.array([[f.k_xx, f.k_xy + f.k_skew], [f.k_xy - f.k_skew, f.k_yy]])
    c = np.array([[f.c_xx, f.c_xy], [f.c_xy, f.c_yy]])
    return k, c


def polar(r: float, phi: float) -> tuple[float, float]:
    return r * math.cos(phi), r * math.sin(phi)


# --- parameters and stiffness ---------------------------------------------------------------------

def test_defaults_match_the_ball_bearing():
    p = ClearanceParameters()
    assert p.radial_clearance == pytest.approx(BearingParameters().radial_clearance / 2) == 1.0e-5
    assert p.bushing_radius == pytest.approx(p.journal_radius + p.radial_clearance)
    assert p.effective_eccentricity_limit == pytest.approx(0.05 * p.journal_radius)
    assert CLEARANCE_PARAMETER_NAMES[0] == "radial_clearance"


def test_sphere_to_sphere_stiffness_by_hand():
    # sigma = (1 - 0.3^2)/207e9 = 4.3961353e-12 1/Pa each; R_i R_j/(R_i - R_j) = 0.01201*0.012/1e-5 = 14.412 m
    sigma = 0.91 / 207e9
    expected = (4.0 / 3.0) / (2.0 * sigma) * math.sqrt(14.412)
    assert expected == pytest.approx(5.757048e11, rel=1e-6)
    assert K == pytest.approx(expected, rel=1e-12)
    # Hertz for two spheres, F = (4/3) E* sqrt(R) delta^1.5, 1/R = 1/R_j - 1/R_i, E* = E/(2(1 - nu^2))
    r = 1.0 / (1.0 / 0.012 - 1.0 / 0.01201)
    assert K == pytest.approx(4.0 / 3.0 * 207e9 / (2 * 0.91) * math.sqrt(r), rel=1e-9)
    # different materials: only sigma_i + sigma_j matters
    assert sphere_contact_stiffness(0.01201, 0.012, 207e9, 0.3, 110e9, 0.34) == pytest.approx(
        (4.0 / 3.0) / (0.91 / 207e9 + (1 - 0.34 ** 2) / 110e9) * math.sqrt(14.412), rel=1e-12)
    # much stiffer than one ball of the bearing (the paper's explanation of Fig. 25)
    assert K / BallBearing().stiffness == pytest.approx(59.4, rel=0.01)


def test_stiffness_override():
    assert ClearanceJoint(ClearanceParameters(contact_stiffness=1.0e10)).stiffness == 1.0e10
    assert ClearanceJoint(ClearanceParameters(radial_clearance=0.0, contact_stiffness=1.0e10)).clearance == 0.0


@pytest.mark.parametrize("name, value", [
    ("radial_clearance", -1e-6), ("radial_clearance", 0.0), ("journal_radius", 0.0),
    ("restitution", 0.0), ("restitution", 1.1), ("youngs_modulus", -1.0), ("poisson_ratio", 0.5),
    ("contact_stiffness", -1.0), ("min_impact_velocity", 0.0), ("eccentricity_limit", -1.0),
    ("eccentricity_limit", 5e-6), ("journal_radius", float("nan")), ("restitution", float("inf")),
])
def test_validation_names_the_parameter(name, value):
    with pytest.raises(BearingParameterError) as info:
        ClearanceJoint(ClearanceParameters(**{name: value}))
    assert info.value.name == name
    assert name in str(info.value) and repr(value) in str(info.value)


def test_check_inputs():
    JOINT.check_inputs(C, 0.0, 1.0, -1.0, 100.0, -3.0)
    for bad in (float("nan"), float("inf"), -float("inf")):
        with pytest.raises(BearingInputError, match="v_y"):
            JOINT.check_inputs(C, 0.0, 0.0, bad)
        with pytest.raises(BearingInputError, match="omega_outer"):
            JOINT.check_inputs(C, 0.0, 0.0, 0.0, 0.0, bad)
    with pytest.raises(BearingInputError, match="eccentricity_limit"):
        JOINT.check_inputs(0.0, 1.01 * JOINT.eccentricity_limit, 0.0, 0.0)


def test_check_inputs_names_the_culprit_past_the_fast_path():
    """check_joint_inputs tests the sum of the inputs first: an inf and a -inf (sum NaN) are still named, and
    finite inputs whose sum overflows are still accepted."""
    inf = float("inf")
    with pytest.raises(BearingInputError, match="v_x"):
        JOINT.check_inputs(0.0, 0.0, inf, -inf)
    with pytest.raises(BearingInputError, match="omega_inner"):
        JOINT.check_inputs(0.0, 0.0, 0.0, 0.0, -inf, inf)
    JOINT.check_inputs(0.0, 0.0, 1e308, 1e308, 1e308, 1e308)   # sum inf, every input finite: fine


# --- force law: closed forms -------------------------------------------------------------------

@pytest.mark.parametrize("r", [0.0, 0.3 * C, 0.999999 * C, C])
def test_no_force_inside_the_clearance(r):
    for phi in np.linspace(0.0, 2 * math.pi, 7):
        f = JOINT.evaluate(*polar(r, phi), 3.0, -2.0, 0.0)
        assert f[:9] == (0.0,) * 9
        assert f.contact_force == 0.0 and f.penetration == pytest.approx(r - C, abs=1e-20)


@pytest.mark.parametrize("delta", [1e-9, 1e-7, 2e-6])
def test_static_force_is_hertz_along_e(delta):
    for phi in (0.0, 0.7, 2.0, -2.9):
        ex, ey = polar(C + delta, phi)
        for iv in (0.0, 0.05, 3.0):            # no velocity: the recorded impact speed does not matter
            f = JOINT.evaluate(ex, ey, 0.0, 0.0, iv)
            fn = K * delta ** 1.5
            assert f.contact_force == pytest.approx(fn, rel=1e-12)
            assert (f.F_x, f.F_y) == pytest.approx((fn * math.cos(phi), fn * math.sin(phi)), rel=1e-9, abs=1e-12 * fn)
            assert f.penetration == pytest.approx(delta, rel=1e-6)
    f = JOINT.evaluate(C + 1e-7, 0.0, 0.0, 0.0, 0.0)
    assert f.F_x > 0 and f.F_y == 0.0            # journal pushed in +x: the housing is pushed along +e
    assert 0.4 * K * 1e-7 ** 2.5 == pytest.approx(JOINT.elastic_energy(C + 1e-7, 0.0), rel=1e-9)


def test_damping_term_and_guard():
    delta, vn = 1e-7, 0.004
    chi_lit = hysteresis_factor(0.9)
    assert chi_lit == pytest.approx(0.75 * 0.19)
    el = K * delta ** 1.5
    # recorded impact speed above the guard: Lankarani-Nikravesh exactly
    f = JOINT.evaluate(C + delta, 0.0, vn, 0.0, 0.2)
    assert f.contact_force == pytest.approx(el * (1 + chi_lit * vn / 0.2), rel=1e-12)
    assert f.c_xx == pytest.approx(el * chi_lit / 0.2, rel=1e-12)
    # below the guard (and 0 = none recorded) the guard's speed is used
    vmin = JOINT.min_impact_velocity
    for iv in (0.0, 1e-9, 0.5 * vmin):
        g = JOINT.evaluate(C + delta, 0.0, vn, 0.0, iv)
        assert g.contact_force == pytest.approx(el * (1 + chi_lit * vn / vmin), rel=1e-12)


def test_no_tension():
    delta = 1e-7
    vmin = JOINT.min_impact_velocity
    pulling = -1.01 * vmin / hysteresis_factor(0.9)        # fast separation: the damping would pull
    f = JOINT.evaluate(0.0, -(C + delta), 0.0, -pulling, 0.0)   # n = -y, v.n = pulling < 0
    assert f.normal_velocity == pytest.approx(pulling)
    assert f[:9] == (0.0,) * 9 and f.contact_force == 0.0 and f.penetration > 0


# --- hysteresis: energy and restitution ------------------------------------------------------------

def test_load_unload_cycle_dissipates_energy():
    """delta = a sin(w t) over half a period: the work on the contact is the hysteresis loop's area."""
    a, w = 5e-7, 2e4
    impact = a * w

    def power(t):
        d, dd = a * math.sin(w * t), a * w * math.cos(w * t)
        f = JOINT.evaluate(C + d, 0.0, dd, 0.0, impact)
        return f.F_x * dd                         # force on the housing along +x times compression rate

    work, _ = quad(power, 0.0, math.pi / w, epsabs=0.0, epsrel=1e-11, limit=200)
    chi = hysteresis_factor(0.9) / impact
    # closed form: K chi a^3.5 w * int_0^pi sin^1.5 cos^2 = K chi a^3.5 w B(5/4, 3/2)
    assert work > 0
    assert work == pytest.approx(K * chi * a ** 3.5 * w * beta(1.25, 1.5), rel=1e-8)


def bounce(joint: ClearanceJoint, v0: float, mass: float = 0.3) -> float:
    """Journal of ``mass`` hitting the bushing wall at v0 [m/s]: the rebound's coefficient of restitution.

    1-DOF along +x: the journal receives -F_x.  The contact state is updated at entry, as the FMU does.
    """
    state = joint.update_state(ContactState(), joint.clearance * (1 + 1e-12), 0.0, v0, 0.0)
    assert state == (True, v0)

    def rhs(t, y):
        f = joint.evaluate(joint.clearance + y[0], 0.0, y[1], 0.0, state.impact_velocity)
        return [y[1], -f.F_x / mass]

    def leaves(t, y):
        return y[0]
    leaves.terminal, leaves.direction = True, -1
    # Hertz contact time ~ 3.2 (m^2 / (K^2 v0))^(1/5)
    tc = (mass ** 2 / (joint.stiffness ** 2 * v0)) ** 0.2
    sol = solve_ivp(rhs, (0.0, 10 * tc), [0.0, v0], method="LSODA", events=leaves, rtol=1e-10,
                    atol=[1e-18, 1e-13], first_step=1e-4 * tc, max_step=0.01 * tc)
    assert sol.status == 1, "the journal did not leave the wall"
    return -sol.y_events[0][0][1] / v0


@pytest.mark.parametrize("v0", [0.02, 0.2, 2.0])
def test_restitution_of_an_impact(v0):
    """Lankarani-Nikravesh is derived for c_r near 1: at c_r = 0.9 the rebound is within a few %."""
    e = bounce(JOINT, v0)
    assert e == pytest.approx(0.9, rel=0.03)
    assert e == pytest.approx(0.91318, abs=2e-4)           # the model's own value, independent of v0 and m
    assert bounce(ClearanceJoint(ClearanceParameters(restitution=0.98)), v0) == pytest.approx(0.98, rel=0.005)


def test_restitution_below_the_guard_tends_to_one():
    """Below min_impact_velocity the law is Hunt-Crossley-like: c_r(v) ~ sqrt(1 - (1 - c_r^2) v / v_min)."""
    vmin = JOINT.min_impact_velocity
    e = bounce(JOINT, 0.1 * vmin)
    assert 0.9 < e < 1.0
    assert e == pytest.approx(math.sqrt(1 - 0.19 * 0.1), abs=2e-3)


# --- tangent matrices, symmetry --------------------------------------------------------------------

CASES = [  # (|e| - c, phi, v_x, v_y, impact velocity)
    (1e-7, 0.0, 0.01, 0.0, 0.05),
    (3e-7, 0.9, 0.02, -0.03, 0.05),
    (2e-6, -2.2, -0.004, 0.05, 0.0),
    (5e-8, 2.9, 0.3, 0.2, 0.4),
]


@pytest.mark.parametrize("delta, phi, vx, vy, iv", CASES)
def test_tangent_matrices_against_finite_differences(delta, phi, vx, vy, iv):
    ex, ey = polar(C + delta, phi)
    f = JOINT.evaluate(ex, ey, vx, vy, iv)
    assert f.contact_force > 0
    k, c = full_jacobian(f)
    he, hv = 1e-6 * delta, 1e-7
    kfd, cfd = np.zeros((2, 2)), np.zeros((2, 2))
    for j in range(2):
        de = np.eye(2)[j]
        fp = JOINT.evaluate(ex + he * de[0], ey + he * de[1], vx, vy, iv)
        fm = JOINT.evaluate(ex - he * de[0], ey - he * de[1], vx, vy, iv)
        kfd[:, j] = [(fp.F_x - fm.F_x) / (2 * he), (fp.F_y - fm.F_y) / (2 * he)]
        fp = JOINT.evaluate(ex, ey, vx + hv * de[0], vy + hv * de[1], iv)
        fm = JOINT.evaluate(ex, ey, vx - hv * de[0], vy - hv * de[1], iv)
        cfd[:, j] = [(fp.F_x - fm.F_x) / (2 * hv), (fp.F_y - fm.F_y) / (2 * hv)]
    assert np.allclose(k, kfd, rtol=1e-6, atol=1e-7 * np.abs(k).max())
    assert np.allclose(c, cfd, rtol=1e-6, atol=1e-9 * np.abs(c).max())


def test_geometric_stiffness_and_skew_part():
    """Without velocity the tangent is (1.5 F_n/delta) n n^T + (F_n/|e|)(I - n n^T), symmetric."""
    delta = 4e-7
    f = JOINT.evaluate(0.0, C + delta, 0.0, 0.0, 0.1)           # n = +y
    fn = K * delta ** 1.5
    assert f.k_yy == pytest.approx(1.5 * fn / delta, rel=1e-12)
    assert f.k_xx == pytest.approx(fn / (C + delta), rel=1e-12)
    assert f.k_xy == pytest.approx(0.0, abs=1e-9 * f.k_yy) and f.k_skew == 0.0
    # a tangential velocity turns n and with it the damping term: dF_y/de_x != dF_x/de_y
    g = JOINT.evaluate(0.0, C + delta, 0.05, 0.01, 0.1)
    assert g.k_skew != 0.0
    assert g.k_skew == pytest.approx(-0.5 * fn * hysteresis_factor(0.9) / 0.1 / (C + delta) * 0.05, rel=1e-9)


@pytest.mark.parametrize("delta, phi, vx, vy, iv", CASES)
def test_rotation_symmetry(delta, phi, vx, vy, iv):
    ex, ey = polar(C + delta, phi)
    f = JOINT.evaluate(ex, ey, vx, vy, iv)
    k, c = full_jacobian(f)
    for theta in (0.4, math.pi / 2, 2.5, -1.3):
        R = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
        e2, v2 = R @ [ex, ey], R @ [vx, vy]
        g = JOINT.evaluate(*e2, *v2, iv)
        scale = f.contact_force
        assert np.allclose([g.F_x, g.F_y], R @ [f.F_x, f.F_y], rtol=1e-9, atol=1e-12 * scale)
        k2, c2 = full_jacobian(g)
        assert np.allclose(k2, R @ k @ R.T, rtol=1e-9, atol=1e-9 * np.abs(k).max())
        assert np.allclose(c2, R @ c @ R.T, rtol=1e-9, atol=1e-9 * np.abs(c).max())
        assert g.contact_force == pytest.approx(f.contact_force, rel=1e-9)
        assert g.penetration == pytest.approx(f.penetration, rel=1e-6)


# --- contact state -------------------------------------------------------------------------------

def test_contact_state_records_the_impact_velocity():
    s0 = ContactState()
    assert s0 == (False, 0.0)
    s = JOINT.update_state(s0, 0.5 * C, 0.0, 0.1, 0.0)            # free flight
    assert s == (False, 0.0)
    s = JOINT.update_state(s, 0.0, -(C + 1e-9), 0.3, -0.07)        # enters at v . n = 0.07
    assert s.in_contact and s.impact_velocity == pytest.approx(0.07)
    s2 = JOINT.update_state(s, 0.0, -(C + 5e-7), 0.0, -0.01)       # stays: the state does not change
    assert s2 == s
    assert JOINT.update_state(s2, 0.0, -0.9 * C, 0.0, 0.5) == (False, 0.0)   # leaves
    # a contact first seen while receding records 0, and gets the guard
    assert JOINT.update_state(s0, C + 1e-8, 0.0, -0.2, 0.0) == (True, 0.0)
    # evaluate_with_state: the state after, and the force for it
    f, s3 = JOINT.evaluate_with_state(s0, C + 2e-7, 0.0, 0.05, 0.0)
    assert s3 == (True, 0.05)
    assert f == JOINT.evaluate(C + 2e-7, 0.0, 0.05, 0.0, 0.05)


# --- the FMU ---------------------------------------------------------------------------------------

FMU_INPUTS = ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")
FMU_OUTPUTS = {  # FMU output -> ClearanceForce field
    "F_x": "F_x", "F_y": "F_y", "stiffness_xx": "k_xx", "stiffness_xy": "k_xy", "stiffness_yy": "k_yy",
    "damping_xx": "c_xx", "damping_xy": "c_xy", "damping_yy": "c_yy", "stiffness_skew": "k_skew",
    "penetration": "penetration", "contact_force": "contact_force", "normal_velocity": "normal_velocity",
}


# ``journal_clearance_fmu``: the session fixture of conftest.py (build_fmu.REGISTRY's build).


class Instance:
    """A JournalClearance FMU instance through fmpy's low-level API, recording log messages."""

    def __init__(self, path: Path, parameters: dict | None = None, initialize: bool = True):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        from mechanism.cosim.fmpy_logging import fmpy_callbacks
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages: list[tuple[int, str, str]] = []

        def logger(component, instance, status, category, message):
            self.messages.append((status, (category or b"").decode(), (message or b"").decode()))

        self.callbacks = fmpy_callbacks(logger)   # fmpy's proxy formats the message; never dangles
        self.unzipdir = extract(str(path))
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="jc")
        self.fmu.instantiate(callbacks=self.callbacks, loggingOn=True)
        self.parameters = dict(parameters or {})
        if initialize:
            self.initialize()

    def initialize(self) -> None:
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in self.parameters.items():
            self.fmu.setReal([self.vr[name]], [value])
        self.fmu.exitInitializationMode()

    def step(self, t: float, h: float, inputs) -> None:
        self.fmu.setReal([self.vr[n] for n in FMU_INPUTS], list(inputs))
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def outputs(self) -> dict[str, float]:
        return dict(zip(FMU_OUTPUTS, self.fmu.getReal([self.vr[n] for n in FMU_OUTPUTS])))

    def state(self) -> ContactState:
        (flag,) = self.fmu.getBoolean([self.vr["in_contact"]])
        (iv,) = self.fmu.getReal([self.vr["impact_velocity"]])
        return ContactState(bool(flag), iv)

    def close(self) -> None:
        self.fmu.terminate()
        self.free()

    def free(self) -> None:
        self.fmu.freeInstance()
        shutil.rmtree(self.unzipdir, ignore_errors=True)


def trajectory(n: int = 40):
    """Inputs through free flight, an impact, sliding contact and separation (s = 200 t)."""
    rows = []
    for i in range(n):
        s = i / (n - 1)
        r = C * (0.5 + 0.6 * math.sin(math.pi * s))            # 0.5 c ... 1.1 c ... 0.5 c
        phi = 0.3 + 2.0 * s
        dr, dphi = C * 0.6 * math.pi * math.cos(math.pi * s) * 200.0, 2.0 * 200.0
        rows.append((r * math.cos(phi), r * math.sin(phi),
                     dr * math.cos(phi) - r * dphi * math.sin(phi), dr * math.sin(phi) + r * dphi * math.cos(phi),
                     120.0 * s, -30.0))
    return rows


def test_fmu_model_description(journal_clearance_fmu):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(journal_clearance_fmu)) == []
    md = read_model_description(str(journal_clearance_fmu))
    assert md.coSimulation.modelIdentifier == "JournalClearance"
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    by_cause = {}
    for v in md.modelVariables:
        by_cause.setdefault(v.causality, []).append(v)
    assert tuple(v.name for v in by_cause["input"]) == FMU_INPUTS
    from fmu_bearing.slaves.ball_bearing_fmu import FORCE_OUTPUTS as BALL_OUTPUTS, INPUTS as BALL_INPUTS
    assert FMU_INPUTS == tuple(name for name, _, _ in BALL_INPUTS)          # a drop-in replacement
    assert all(v.unit for v in by_cause["input"])
    outputs = {v.name: v for v in by_cause["output"]}
    assert set(FMU_OUTPUTS) | {"in_contact", "impact_velocity"} == set(outputs)
    assert {name for name, unit, _ in BALL_OUTPUTS if unit is not None and name != "max_ball_load"} <= set(outputs)
    assert all(v.initial == "calculated" and v.start is None for v in outputs.values())   # computed at initialisation
    assert [u.variable.name for u in md.initialUnknowns] == list(outputs)
    assert outputs["F_x"].unit == "N" and outputs["damping_xy"].unit == "N.s/m"
    params = {v.name: v for v in by_cause["parameter"]}
    assert tuple(params) == CLEARANCE_PARAMETER_NAMES
    defaults = ClearanceParameters()
    for name, v in params.items():
        assert float(v.start) == getattr(defaults, name) and v.unit and v.description


def test_fmu_outputs_equal_the_law(journal_clearance_fmu):
    params = {"restitution": 0.8, "min_impact_velocity": 1e-3}
    joint = ClearanceJoint(ClearanceParameters(**params))
    inst = Instance(journal_clearance_fmu, params)
    try:
        state, t, h = ContactState(), 0.0, 1e-4
        seen = set()
        for inputs in trajectory():
            inst.step(t, h, inputs)
            t += h
            force, state = joint.evaluate_with_state(state, *inputs[:4])
            out = inst.outputs()
            for name, field in FMU_OUTPUTS.items():
                ref = getattr(force, field)
                assert out[name] == pytest.approx(ref, rel=1e-12, abs=1e-12 * max(1.0, abs(ref))), name
            fmu_state = inst.state()
            assert fmu_state.in_contact is state.in_contact
            assert fmu_state.impact_velocity == pytest.approx(state.impact_velocity, rel=1e-12, abs=0.0)
            seen.add((state.in_contact, force.contact_force > 0))
        assert seen == {(False, False), (True, True)}, "the trajectory must cover free flight and contact"
    finally:
        inst.close()


def test_fmu_nan_input_is_an_error(journal_clearance_fmu):
    from fmpy.fmi1 import FMICallException
    inst = Instance(journal_clearance_fmu)
    try:
        inst.step(0.0, 1e-4, (C + 1e-7, 0.0, 0.1, 0.0, 0.0, 0.0))
        before, state = inst.outputs(), inst.state()
        with pytest.raises(FMICallException) as info:
            inst.step(1e-4, 1e-4, (C, float("nan"), 0.0, 0.0, 0.0, 0.0))
        assert info.value.status >= 2                          # discard: pythonfmu's non-fatal failure
        errors = [m for m in inst.messages if m[0] == 3]       # logged with Fmi2Status.error
        assert errors and "e_y" in errors[-1][2] and "not a finite number" in errors[-1][2]
        assert inst.state() == state and inst.outputs() == before   # nothing advanced: the master may retry
        with pytest.raises(FMICallException):
            inst.step(2e-4, 1e-4, (0.0, 0.0, 0.0, 0.0, 0.0, float("inf")))
        with pytest.raises(FMICallException):
            inst.step(2e-4, 1e-4, (0.0, 1.0, 0.0, 0.0, 0.0, 0.0))  # |e| beyond the divergence limit
        assert "eccentricity_limit" in inst.messages[-1][2]
        inst.step(2e-4, 1e-4, (C + 1e-7, 0.0, 0.1, 0.0, 0.0, 0.0))  # still usable
        assert inst.outputs()["F_x"] > 0
    finally:
        inst.close()


def test_fmu_state_save_restore(journal_clearance_fmu):
    inst = Instance(journal_clearance_fmu)
    try:
        inst.step(0.0, 1e-4, (0.5 * C, 0.0, 0.2, 0.0, 0.0, 0.0))
        inst.step(1e-4, 1e-4, (C + 1e-8, 0.0, 0.2, 0.0, 0.0, 0.0))     # impact at 0.2 m/s
        assert inst.state() == (True, pytest.approx(0.2))
        saved = inst.fmu.getFMUstate()
        blob = inst.fmu.serializeFMUstate(saved)
        follow = (C + 3e-7, 0.0, 0.05, 0.0, 0.0, 0.0)
        inst.step(2e-4, 1e-4, follow)
        expected = inst.outputs()
        assert expected["contact_force"] == pytest.approx(
            JOINT.evaluate(*follow[:4], 0.2).contact_force, rel=1e-12)
        # leave the contact and re-enter slowly: the recorded impact velocity changes
        inst.step(3e-4, 1e-4, (0.5 * C, 0.0, 0.0, 0.0, 0.0, 0.0))
        inst.step(4e-4, 1e-4, (C + 1e-8, 0.0, 0.001, 0.0, 0.0, 0.0))
        assert inst.state() == (True, pytest.approx(0.001))
        for restore in ("state", "serialized"):
            if restore == "state":
                inst.fmu.setFMUstate(saved)
            else:
                inst.fmu.setFMUstate(inst.fmu.deSerializeFMUstate(blob))
            assert inst.state() == (True, pytest.approx(0.2))
            inst.step(2e-4, 1e-4, follow)
            assert inst.outputs() == expected
        inst.fmu.freeFMUstate(saved)
    finally:
        inst.close()


def test_fmu_rejects_invalid_parameters(journal_clearance_fmu):
    from fmpy.fmi1 import FMICallException
    inst = Instance(journal_clearance_fmu, {"restitution": 1.5}, initialize=False)
    with pytest.raises(FMICallException) as info:
        inst.initialize()
    assert info.value.status == 3    # raised in Python: pythonfmu says fmi2Fatal, the loader fmi2Error
    assert any(m[0] >= 3 and "restitution = 1.5" in m[2] for m in inst.messages)   # logged: names the parameter
    inst.free()


def test_fmu_refuses_setting_parameters_after_initialisation(journal_clearance_fmu):
    """Refused and logged, never raised inside the FMU (pythonfmu 0.7 crashes on that path); value unchanged."""
    inst = Instance(journal_clearance_fmu)
    before = inst.fmu.getReal([inst.vr["restitution"]])
    inst.fmu.setReal([inst.vr["restitution"]], [0.5])
    assert any("restitution is fixed" in m[2] for m in inst.messages)
    assert inst.fmu.getReal([inst.vr["restitution"]]) == before
    inst.free()
    inst = Instance(journal_clearance_fmu)
    inst.fmu.setReal([inst.vr["F_x"]], [1.0])
    assert any("F_x is an output" in m[2] for m in inst.messages)
    assert inst.fmu.getReal([inst.vr["F_x"]]) != [1.0]
    inst.free()


def test_build_registry_has_the_fmu():
    build_fmu = pytest.importorskip("build_fmu")
    specs = {spec.name: spec for spec in build_fmu.REGISTRY}
    assert Path(specs["JournalClearance"].script).resolve() == SLAVE
