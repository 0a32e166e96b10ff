"""The BUILT BallBearing3 FMU (FMI 3.0, pythonfmu3) through fmpy: a clean ``fmpy validate``, the same forces as
the FMI 2.0 BallBearing FMU (both driven through fmpy's low-level API), the ``ball_loads`` array sized by the
structural parameter ``n_balls``, FMU state, and bad parameters/inputs giving an error status, never a crash."""
from __future__ import annotations

import ctypes
import json
import math
import os
import subprocess
import sys
import textwrap
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free)
from fmpy.fmi3 import FMU3Slave
from fmpy.logging import addLoggerProxy
from fmpy.validation import validate_fmu

from conftest import built_fmu
from fmu_bearing.life import LIFE_OUTPUTS, RATING_OUTPUTS
from fmu_bearing.parameters import BearingParameters
from fmu_bearing.slaves.stepping import LIFE_STATE

ROOT = Path(__file__).resolve().parent.parent
INPUTS = ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")
SCALARS = ("F_x", "F_y", "stiffness_xx", "stiffness_xy", "stiffness_yy", "damping_xx", "damping_xy",
           "damping_yy", "max_ball_load", "cage_angle")
HALF = BearingParameters().radial_clearance / 2
DISCARD, ERROR = 2, 3


@pytest.fixture(scope="module")
def fmu3(tmp_path_factory) -> Path:
    return built_fmu("BallBearing3", tmp_path_factory)


class Slave3:
    """One FMU3Slave instance: structural and other parameters in Configuration/Initialization Mode."""

    def __init__(self, path: Path, params=None, inputs=(0.0,) * 6, name="bearing3"):
        self.md = read_model_description(str(path))
        self.var = {v.name: v for v in self.md.modelVariables}
        self.vr = {n: v.valueReference for n, v in self.var.items()}
        self.messages = []
        self.dir = extract(str(path))
        self.s = FMU3Slave(guid=self.md.guid, unzipDirectory=self.dir,
                           modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.s.instantiate(loggingOn=True, logMessage=self._log)
        params = dict(params or {})
        if "n_balls" in params:
            self.s.enterConfigurationMode()
            self.s.setUInt64([self.vr["n_balls"]], [int(params.pop("n_balls"))])
            self.s.exitConfigurationMode()
        self.s.enterInitializationMode()
        for k, value in params.items():
            self.set(k, value)
        self.s.setFloat64([self.vr[n] for n in INPUTS], [float(x) for x in inputs])

    def _log(self, env, status, category, message):
        self.messages.append((status, category.decode(), message.decode("utf-8", "replace")))

    def set(self, name, value):
        t, vr = self.var[name].type, [self.vr[name]]
        if t == "Int32":
            self.s.setInt32(vr, [int(value)])
        elif t == "Boolean":
            self.s.setBoolean(vr, [bool(value)])
        else:
            self.s.setFloat64(vr, [float(value)])

    def n_balls(self) -> int:
        return int(self.s.getUInt64([self.vr["n_balls"]])[0])

    def outputs(self):
        """SCALARS, ball loads (n_balls of them), loaded_balls."""
        loads = self.s.getFloat64([self.vr["ball_loads"]], nValues=self.n_balls())
        return (self.s.getFloat64([self.vr[n] for n in SCALARS]) + loads
                + [float(self.s.getInt32([self.vr["loaded_balls"]])[0])])

    def step(self, t, h, inputs):
        self.s.setFloat64([self.vr[n] for n in INPUTS], [float(x) for x in inputs])
        self.s.doStep(t, h)

    def free(self):
        self.s.terminate()
        self.s.freeInstance()


class Slave2:
    """One FMU2Slave instance of the FMI 2.0 BallBearing FMU (per-ball outputs ball_load_1..capacity)."""

    def __init__(self, path: Path, params=None, inputs=(0.0,) * 6):
        self.md = read_model_description(str(path))
        self.var = {v.name: v for v in self.md.modelVariables}
        self.vr = {n: v.valueReference for n, v in self.var.items()}
        self.dir = extract(str(path))
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(lambda *args: None)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(ctypes.byref(self.callbacks))
        self.s = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                           modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="bearing2")
        self.s.instantiate(callbacks=self.callbacks)
        self.s.setupExperiment(startTime=0.0)
        self.s.enterInitializationMode()
        for k, value in dict(params or {}).items():
            t, vr = self.var[k].type, [self.vr[k]]
            if t == "Integer":
                self.s.setInteger(vr, [int(value)])
            elif t == "Boolean":
                self.s.setBoolean(vr, [bool(value)])
            else:
                self.s.setReal(vr, [float(value)])
        self.s.setReal([self.vr[n] for n in INPUTS], [float(x) for x in inputs])
        self.n = int((params or {}).get("n_balls", BearingParameters().n_balls))

    def outputs(self):
        loads = [self.vr[f"ball_load_{r + 1}"] for r in range(self.n)]
        return (self.s.getReal([self.vr[n] for n in SCALARS] + loads)
                + [float(self.s.getInteger([self.vr["loaded_balls"]])[0])])

    def step(self, t, h, inputs):
        self.s.setReal([self.vr[n] for n in INPUTS], [float(x) for x in inputs])
        self.s.doStep(t, h)

    def free(self):
        self.s.terminate()
        self.s.freeInstance()


def random_inputs(rng):
    a = rng.uniform(0, 2 * math.pi)
    radius = rng.uniform(0, HALF) if rng.uniform() < 0.2 else rng.uniform(HALF, 8e-5)  # some inside the clearance
    return (radius * math.cos(a), radius * math.sin(a), *rng.normal(0, 0.02, 2), *rng.normal(0, 200, 2))


# --- modelDescription --------------------------------------------------------------------------

def test_fmpy_validate_finds_no_problems(fmu3):
    assert validate_fmu(str(fmu3)) == []
    result = subprocess.run([sys.executable, "-m", "fmpy", "validate", str(fmu3)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and "No problems found" in result.stdout, result.stdout + result.stderr


def test_model_description_has_the_fmi2_interface_with_one_array_of_ball_loads(fmu3, ball_bearing_fmu):
    md3, md2 = read_model_description(str(fmu3)), read_model_description(str(ball_bearing_fmu))
    assert md3.fmiVersion == "3.0" and md3.modelName == "BallBearing3"
    assert md3.coSimulation.canGetAndSetFMUstate and md3.coSimulation.canSerializeFMUstate
    v3 = {v.name: v for v in md3.modelVariables}
    v2 = {v.name: v for v in md2.modelVariables}
    # same inputs, outputs (incl. ratings and life; but the per-ball loads) and parameters, same units and defaults
    names2 = {n for n in v2 if not n.startswith("ball_load_")}
    assert names2 <= set(v3) and set(v3) - names2 == {"ball_loads", "time"}
    for name in names2:
        assert v3[name].causality == v2[name].causality or name == "n_balls", name
        assert v3[name].unit == v2[name].unit, name
        if v2[name].causality in ("parameter", "input") and v2[name].type == "Real":
            assert float(v3[name].start) == float(v2[name].start), name
    assert [v.name for v in md3.modelVariables if v.causality == "parameter"] == \
        [f.name for f in fields(BearingParameters) if f.name != "n_balls"]
    n_balls, loads = v3["n_balls"], v3["ball_loads"]
    assert (n_balls.causality, n_balls.type, int(n_balls.start)) == ("structuralParameter", "UInt64", 8)
    assert loads.causality == "output" and loads.unit == "N" and loads.initial == "calculated"
    assert [d.variable.name for d in loads.dimensions] == ["n_balls"] and list(loads.shape) == [8]
    # every unit used is declared, with its SI base-unit exponents
    units = {u.name: u for u in md3.unitDefinitions}
    assert units["N"].baseUnit.kg == 1 and units["N"].baseUnit.m == 1 and units["N"].baseUnit.s == -2
    assert units["N.s/m"].baseUnit.kg == 1 and units["N.s/m"].baseUnit.s == -1
    for v in md3.modelVariables:
        if v.type == "Float64":
            assert v.unit in units, v.name
        if v.causality == "output":
            assert v.initial == "calculated", v.name  # computed when initialisation ends


# --- the same forces as the FMI 2.0 FMU --------------------------------------------------------

@pytest.mark.parametrize("params", [
    {},
    {"n_balls": 12, "damping_model": 0, "cage_angle_start": 0.3},
    {"n_balls": 15, "allow_ball_overlap": True, "damping_model": 2},
], ids=["table2", "12-balls-undamped", "15-balls-oil-film"])
def test_same_outputs_as_the_fmi2_fmu(fmu3, ball_bearing_fmu, params):
    rng = np.random.default_rng(13)
    start = random_inputs(rng)
    a, b = Slave3(fmu3, params, start), Slave2(ball_bearing_fmu, params, start)
    try:
        a.s.exitInitializationMode()
        b.s.exitInitializationMode()
        compared = 0
        t = 0.0
        for k in range(60):
            out3, out2 = np.array(a.outputs()), np.array(b.outputs())
            assert len(out3) == len(SCALARS) + b.n + 1
            np.testing.assert_allclose(out3, out2, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(out2).max()))
            compared += int(out2[0] != 0.0)
            h = float(rng.choice([1e-6, 1e-5, 5e-5]))
            inputs = random_inputs(rng)
            a.step(t, h, inputs)
            b.step(t, h, inputs)
            t += h
        assert compared > 30  # most points carry load: the comparison is not of zeros
    finally:
        a.free()
        b.free()


# --- the ball_loads array ----------------------------------------------------------------------

@pytest.mark.parametrize("n", [3, 8, 25])
def test_ball_loads_has_n_balls_entries_and_sums_to_the_force(fmu3, n):
    """25 balls: more than the FMI 2.0 FMU's default capacity (20); the array has no capacity."""
    e, cage = (3.1e-5, -1.2e-5), 0.2
    params = {"n_balls": n, "damping_model": 0, "cage_angle_start": cage, "allow_ball_overlap": n > 10}
    s = Slave3(fmu3, params, (*e, 0.0, 0.0, 0.0, 0.0))
    try:
        s.s.exitInitializationMode()
        assert s.n_balls() == n
        loads = s.s.getFloat64([s.vr["ball_loads"]], nValues=n)
        assert len(loads) == n and all(x >= 0.0 for x in loads) and max(loads) > 0.0
        # eq. (19): the resultant is the sum of the ball loads along the ball directions (eq. 17)
        phi = cage + 2 * np.pi * np.arange(n) / n
        fx, fy = s.s.getFloat64([s.vr["F_x"], s.vr["F_y"]])
        np.testing.assert_allclose([np.dot(loads, np.cos(phi)), np.dot(loads, np.sin(phi))], [fx, fy],
                                   rtol=1e-12)
        assert s.s.getInt32([s.vr["loaded_balls"]])[0] == sum(1 for x in loads if x > 0)
        # the array together with a scalar in one call: n_balls values for the array, then the scalar
        both = s.s.getFloat64([s.vr["ball_loads"], s.vr["F_x"]], nValues=n + 1)
        assert both == loads + [fx]
    finally:
        s.free()


def test_fmu_state_restores_outputs_and_cage_angle(fmu3):
    rng = np.random.default_rng(3)
    s = Slave3(fmu3, {"n_balls": 10}, random_inputs(rng))
    try:
        s.s.exitInitializationMode()
        s.step(0.0, 1e-5, random_inputs(rng))
        state = s.s.getFMUState()
        serialized = s.s.serializeFMUState(state)
        saved = s.outputs()
        later = random_inputs(rng)
        s.step(1e-5, 1e-5, later)
        after = s.outputs()
        s.s.setFMUState(state)
        assert s.outputs() == saved
        s.step(1e-5, 1e-5, later)
        assert s.outputs() == after
        restored = s.s.deserializeFMUState(serialized)
        s.s.setFMUState(restored)
        assert s.outputs() == saved
        s.s.freeFMUState(state)
        s.s.freeFMUState(restored)
    finally:
        s.free()


# --- bearing life: the FMI 2.0 FMU's outputs (docs/bearing-life.md) ----------------------------

LIFE = [name for name, *_ in RATING_OUTPUTS + LIFE_OUTPUTS]


def life3(s: Slave3) -> list[float]:
    return s.s.getFloat64([s.vr[n] for n in LIFE])


def life2(s: Slave2) -> list[float]:
    return s.s.getReal([s.vr[n] for n in LIFE])


def assert_same_life(out3, out2):
    """To 1e-12 relative; an infinite life in both (before any ball is loaded) counts as equal."""
    assert [math.isinf(x) for x in out3] == [math.isinf(x) for x in out2], (out3, out2)
    np.testing.assert_allclose(out3, out2, rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("params", [
    {},
    {"n_balls": 12, "radial_clearance": -5e-6, "reliability_factor": 0.64},
], ids=["table2", "12-balls-preload-a1"])
def test_life_outputs_equal_the_fmi2_fmu_also_after_a_rollback(fmu3, ball_bearing_fmu, params):
    """Both FMUs through fmpy, the same inputs and steps: ratings at initialisation, life infinite before any
    relative rotation, then equal life after 20 steps, after 20 more, after getFMUState/setFMUState back to
    step 20 (and a serialized FMI 3.0 state), and after 20 other steps from there."""
    rng = np.random.default_rng(29)
    a, b = Slave3(fmu3, params), Slave2(ball_bearing_fmu, params)   # at rest, centred: no relative rotation
    try:
        a.s.exitInitializationMode()
        b.s.exitInitializationMode()
        at_start = life3(a)
        assert_same_life(at_start, life2(b))
        assert at_start[3:5] == [0.0, 0.0] and math.isinf(at_start[5]) and math.isinf(at_start[6])
        assert 1e3 < at_start[0] < 1e5            # C_r of Table 2 geometry: about 15 kN (docs/bearing-life.md)
        t = 0.0

        def steps(n):
            nonlocal t
            for _ in range(n):
                h, inputs = float(rng.choice([1e-6, 1e-5, 5e-5])), random_inputs(rng)
                a.step(t, h, inputs)
                b.step(t, h, inputs)
                t += h

        steps(20)
        saved3, saved2, t_saved = life3(a), life2(b), t
        assert_same_life(saved3, saved2)
        assert 0.0 < saved3[5] < math.inf and saved3[3] > 0.0 and saved3[4] > 0.0
        state3, state2 = a.s.getFMUState(), b.s.getFMUstate()
        serialized3 = a.s.serializeFMUState(state3)
        steps(20)
        later3 = life3(a)
        assert_same_life(later3, life2(b))
        assert later3[5:] != saved3[5:]                       # the life has moved on: the rollback shows
        a.s.setFMUState(state3)
        b.s.setFMUstate(state2)
        assert life3(a) == saved3 and life2(b) == saved2      # each FMU exactly back
        t = t_saved
        steps(20)                                             # other inputs from the restored point
        redone3 = life3(a)
        assert_same_life(redone3, life2(b))
        assert redone3[5:] != later3[5:]
        restored3 = a.s.deserializeFMUState(serialized3)      # the serialized state rolls the life back too
        a.s.setFMUState(restored3)
        b.s.setFMUstate(state2)
        assert life3(a) == saved3
        t = t_saved
        steps(5)
        assert_same_life(life3(a), life2(b))
        for st in (state3, restored3):
            a.s.freeFMUState(st)
        b.s.freeFMUstate(state2)
    finally:
        a.free()
        b.free()


def saved_state_then_a_step(s, rng) -> dict:
    """Initialise ``s``, take a step, save its serialized state (parsed), take another step; the state."""
    s.s.exitInitializationMode()
    s.step(0.0, 1e-5, random_inputs(rng))
    state = s.s.getFMUState()
    saved = json.loads(s.s.serializeFMUState(state).rstrip(b"\0").decode())
    s.s.freeFMUState(state)
    s.step(1e-5, 1e-5, random_inputs(rng))
    return saved


def set_serialized_state(s, state: dict) -> None:
    """fmi3DeserializeFMUState of ``state`` as JSON, then fmi3SetFMUState and fmi3FreeFMUState."""
    restored = s.s.deserializeFMUState(json.dumps(state).encode())
    s.s.setFMUState(restored)
    s.s.freeFMUState(restored)


def test_invalid_life_sums_in_a_state_are_refused_before_anything_is_assigned(fmu3):
    """A serialized state whose life accumulator is missing or invalid: setFMUState assigns nothing (outputs,
    cage angle and life unchanged), and the next doStep is refused with a message naming the accumulator."""
    rng = np.random.default_rng(5)
    s = Slave3(fmu3, {}, random_inputs(rng))
    try:
        saved = saved_state_then_a_step(s, rng)
        now, life_now = s.outputs(), life3(s)
        assert saved[LIFE_STATE] and saved["cage_angle"] != s.s.getFloat64([s.vr["cage_angle"]])[0]
        for bad in ([-1.0, 0.0, 1.0, 1.0], [1.0, 2.0], "x", None):
            broken = dict(saved)
            if bad is None:
                del broken[LIFE_STATE]
            else:
                broken[LIFE_STATE] = bad
            set_serialized_state(s, broken)
            assert s.outputs() == now and life3(s) == life_now
            assert "life accumulator" in s.messages[-1][2], s.messages[-1]
            with pytest.raises(FMICallException) as err:
                s.s.doStep(2e-5, 1e-5)
            assert err.value.status == DISCARD
            assert s.outputs() == now and life3(s) == life_now
    finally:
        s.free()


def test_non_finite_values_in_a_state_are_refused_before_anything_is_assigned(fmu3):
    """JSON carries NaN and Infinity: a serialized state with one in an input, output or the ball loads is
    refused (nothing assigned, the message names the variable, the next doStep is refused), as in FMI 2.0."""
    rng = np.random.default_rng(6)
    s = Slave3(fmu3, {}, random_inputs(rng))
    try:
        saved = saved_state_then_a_step(s, rng)
        now = s.outputs()
        for name, bad in (("F_x", float("nan")), ("e_y", float("inf")), ("cage_angle", -float("inf")),
                          ("ball_loads", [float("nan")] * len(saved["ball_loads"]))):
            broken = dict(saved, **{name: bad})
            set_serialized_state(s, broken)
            assert s.outputs() == now
            assert name in s.messages[-1][2] and "not finite" in s.messages[-1][2], s.messages[-1]
            with pytest.raises(FMICallException) as err:
                s.s.doStep(2e-5, 1e-5)
            assert err.value.status == DISCARD
            assert s.outputs() == now
    finally:
        s.free()


def test_state_values_of_the_wrong_type_or_of_another_instance_are_refused(fmu3):
    """Nothing in a serialized state is converted (issue 14: the state is checked completely): a string in a
    Float64, a fraction in an Int32 or the UInt64 n_balls, a number in a Boolean, an unknown key, a state with
    another n_balls (which sizes ball_loads) or, once initialised, other parameter values is refused; nothing
    is assigned, the message names the variable, and the next doStep is refused."""
    rng = np.random.default_rng(7)
    s = Slave3(fmu3, {}, random_inputs(rng))
    try:
        saved = saved_state_then_a_step(s, rng)
        now, life_now = s.outputs(), life3(s)
        n = saved["n_balls"]
        cases = (("e_x", {"e_x": str(saved["e_x"])}),
                 ("damping_model", {"damping_model": 1.7}),
                 ("damping_model", {"damping_model": float(saved["damping_model"])}),
                 ("n_balls", {"n_balls": float(n)}),
                 ("allow_ball_overlap", {"allow_ball_overlap": 0}),
                 ("F_x", {"F_x": True}),
                 ("injected", {"injected": 1.0}),
                 ("n_balls", {"n_balls": n + 1, "ball_loads": saved["ball_loads"] + [0.0]}),
                 ("ball_loads", {"ball_loads": saved["ball_loads"][:-1]}),
                 ("ball_loads", {"ball_loads": [-1.0] * n}),
                 ("damping_coefficient", {"damping_coefficient": saved["damping_coefficient"] * 2.0}))
        for name, change in cases:
            set_serialized_state(s, dict(saved, **change))
            assert s.outputs() == now and life3(s) == life_now, name
            assert name in s.messages[-1][2], (name, s.messages[-1])
            with pytest.raises(FMICallException) as err:
                s.s.doStep(2e-5, 1e-5)
            assert err.value.status == DISCARD
            assert s.outputs() == now and life3(s) == life_now, name
        set_serialized_state(s, saved)        # the state itself is still accepted, and restores the outputs
        assert s.outputs() != now
        s.s.doStep(2e-5, 1e-5)
    finally:
        s.free()


# --- errors: a status and a message, never a crash ---------------------------------------------

def test_refused_step_keeps_the_last_good_outputs(fmu3):
    s = Slave3(fmu3, {}, (2e-5, 0, 0, 0, 100.0, 0))
    try:
        s.s.exitInitializationMode()
        good = s.outputs()
        with pytest.raises(FMICallException) as err:
            s.step(0.0, 1e-5, (1.0, 0, 0, 0, 100.0, 0))      # |e| = 1 m: the master has diverged
        assert err.value.status == DISCARD
        assert s.messages[-1][:2] == (ERROR, "logStatusError") and "eccentricity" in s.messages[-1][2]
        assert s.outputs() == good
        with pytest.raises(FMICallException):
            s.s.setUInt64([s.vr["n_balls"]], [9])                 # a structural parameter after initialisation
            s.step(0.0, 1e-5, (2e-5, 0, 0, 0, 100.0, 0))
        assert any("n_balls" in m for _, _, m in s.messages)
        assert s.n_balls() == 8
        s.step(0.0, 1e-5, (2e-5, 0, 0, 0, 100.0, 0))               # the next good step works again
    finally:
        s.free()


BAD_PARAMETERS = [({"n_balls": 2}, "n_balls"), ({"n_balls": 20}, "n_balls"), ({"n_balls": 10**6}, "n_balls"),
                  ({"poisson_ratio": 0.7}, "poisson_ratio"), ({"damping_model": 5}, "damping_model"),
                  ({"ball_diameter": -1.0}, "ball_diameter"), ({"youngs_modulus": float("nan")}, "youngs_modulus")]


def test_bad_parameters_give_an_error_status_and_name_the_parameter(fmu3):
    """In a child process (a crash must not take pytest with it): every bad set fails
    fmi3ExitInitializationMode with a non-OK status and a logger message naming the parameter, the instance
    is freed, a good instance still works afterwards, and the process exits with status 0."""
    script = textwrap.dedent(f"""
        import sys
        sys.path[:0] = [{str(ROOT / 'tests')!r}, {str(ROOT)!r}]
        from pathlib import Path
        from fmpy.fmi1 import FMICallException
        from test_fmu3 import Slave3, BAD_PARAMETERS
        path = Path({str(fmu3)!r})
        for params, name in BAD_PARAMETERS * 2:
            s = Slave3(path, params, (2e-5, 0, 0, 0, 0, 0))
            try:
                s.s.exitInitializationMode()
                print("ACCEPTED", params)
            except FMICallException as err:
                named = any(name in m and "initialisation failed" in m for _, _, m in s.messages)
                print("REFUSED", err.status, named, params)
            s.s.freeInstance()
        s = Slave3(path, {{}}, (2e-5, 0, 0, 0, 0, 0))
        s.s.exitInitializationMode()
        print("GOOD", s.s.getFloat64([s.vr["F_x"]])[0] > 0)
        s.free()
    """)
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                            cwd=str(ROOT))
    assert result.returncode == 0, result.stdout + result.stderr
    lines = result.stdout.splitlines()
    refused = [line for line in lines if line.startswith("REFUSED")]
    assert len(refused) == 2 * len(BAD_PARAMETERS), result.stdout
    assert all(line.split()[1] in (str(ERROR), "4") and line.split()[2] == "True" for line in refused), result.stdout
    assert "GOOD True" in lines


# --- the master drives either FMU ----------------------------------------------------------------

def test_cosimulated_slider_crank_through_fmi3_equals_the_fmi2_run(fmu3, ball_bearing_fmu):
    """0.1 crank revolution at 1200 rpm, 10 balls, co-simulated through each FMU (the run driver picks the
    endpoint from the FMU's fmiVersion): every recorded column agrees to 1e-12 (relative to its scale)."""
    import mechanism.run as run_module
    from mechanism.cosim.endpoints import Fmu3Endpoint, FmuEndpoint, fmu_endpoint

    for path, kind in ((fmu3, Fmu3Endpoint), (ball_bearing_fmu, FmuEndpoint)):
        with fmu_endpoint(path) as endpoint:
            assert type(endpoint) is kind
    results = {}
    for path in (ball_bearing_fmu, fmu3):
        # jacobian-implicit: both endpoints run the same compiled loop (law-model, the default, runs the Python
        # loop through an FMI 3 endpoint: the same figures to 1e-11 of a column's scale, not to the bit)
        config = run_module.RunConfig(revs=0.1, balls=10, settings={"allow_ball_overlap": True}, fmu=str(path),
                                      progress=False, scheme="jacobian-implicit")
        results[path] = run_module.run(config)
    r2, r3 = results[ball_bearing_fmu], results[fmu3]
    assert r2.ok and r3.ok and r2.data.shape[0] == r3.data.shape[0] == 501
    assert r3.ball_load_columns == [f"ball_load_{k + 1}" for k in range(10)]
    assert set(r3.columns) <= set(r2.columns)
    for column in r3.columns:
        scale = max(1.0, float(np.nanmax(np.abs(r2[column]))))
        np.testing.assert_allclose(r3[column], r2[column], rtol=0, atol=1e-12 * scale, err_msg=column)
    for column in set(r2.ball_load_columns) - set(r3.ball_load_columns):  # FMI 2 capacity beyond n_balls
        assert not np.any(r2[column])
    assert np.nanmax(np.abs(r3["F_x"])) > 100.0  # the bearing carried load


def test_adaptive_run_through_fmi3_restores_fmu_states_like_the_fmi2_run(fmu3, ball_bearing_fmu):
    """The adaptive driver saves and restores the component's FMU state (fmi3GetFMUState/SetFMUState through
    the FMI 3 endpoint): with rejected steps, the run equals the FMI 2 run column for column."""
    from mechanism.run import RunConfig, run_adaptive

    # jacobian-implicit inside: law-model (the default) gives the controller no step to reject at this tolerance
    runs = {p: run_adaptive(RunConfig(revs=0.02, fmu=str(p), progress=False, output_interval=1e-4,
                                      scheme="jacobian-implicit"), tol=1e-3)
            for p in (ball_bearing_fmu, fmu3)}
    r2, r3 = runs[ball_bearing_fmu], runs[fmu3]
    assert r2.ok and r3.ok and r3.meta["rejected_steps"] > 0 and r3.meta["state_restores"] > 0
    assert r3.meta["accepted_steps"] == r2.meta["accepted_steps"]
    for column in r3.columns:
        scale = max(1.0, float(np.nanmax(np.abs(r2[column]))))
        np.testing.assert_allclose(r3[column], r2[column], rtol=0, atol=1e-12 * scale, err_msg=column)


NO_NUMPY_HOST = r'''
import ctypes, importlib.abc, sys
BLOCKED = set(sys.argv[3].split(","))

class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"{name} is blocked in this host")
sys.meta_path.insert(0, Block())

unzipped, token = sys.argv[1], sys.argv[2]
lib = ctypes.CDLL(f"{unzipped}/binaries/x86_64-linux/BallBearing3.so")
LOG = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p)
log = LOG(lambda env, status, category, message: print("LOG", status, message.decode()))
lib.fmi3InstantiateCoSimulation.restype = ctypes.c_void_p
lib.fmi3InstantiateCoSimulation.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_bool,
    ctypes.c_bool, ctypes.c_bool, ctypes.c_bool, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, LOG, ctypes.c_void_p]
inst = lib.fmi3InstantiateCoSimulation(b"b3", token.encode(), f"{unzipped}/resources/".encode(), False, True,
                                       False, False, None, 0, None, log, None)
assert inst, "instantiate failed"
inst = ctypes.c_void_p(inst)
vr = (ctypes.c_uint32 * 6)(0, 1, 2, 3, 4, 5)
u = (ctypes.c_double * 6)(2.5e-5, -1e-5, 0.0, 0.0, 100.0, 0.0)
lib.fmi3EnterInitializationMode.argtypes = [ctypes.c_void_p, ctypes.c_bool, ctypes.c_double, ctypes.c_double,
                                            ctypes.c_bool, ctypes.c_double]
assert lib.fmi3EnterInitializationMode(inst, False, 0.0, 0.0, False, 0.0) == 0
assert lib.fmi3SetFloat64(inst, vr, 6, u, 6) == 0
assert lib.fmi3ExitInitializationMode(inst) == 0
flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
lib.fmi3DoStep.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_bool] + [ctypes.c_void_p] * 4
assert lib.fmi3DoStep(inst, 0.0, 1e-5, False, *[ctypes.addressof(f) for f in flags]) == 0
out = (ctypes.c_double * 2)()
assert lib.fmi3GetFloat64(inst, (ctypes.c_uint32 * 2)(6, 7), 2, out, 2) == 0
print("F", repr(out[0]), repr(out[1]))
print("MODULES", ",".join(sorted(m for m in sys.modules if m.split(".")[0] in ("numpy", "scipy"))))
lib.fmi3FreeInstance(inst)
'''


def _no_numpy_host(fmu3, tmp_path, blocked):
    md = read_model_description(str(fmu3))
    unzipped = extract(str(fmu3), unzipdir=str(tmp_path / "fmu"))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    result = subprocess.run([sys.executable, "-c", NO_NUMPY_HOST, unzipped, md.guid, ",".join(blocked)],
                            capture_output=True, text=True, timeout=120, cwd=str(tmp_path), env=env)
    return result, Path(unzipped)


def test_runs_in_a_host_that_cannot_import_numpy(fmu3, tmp_path):
    """A Python host without fmpy, in which numpy and scipy cannot be imported, drives the FMU through ctypes:
    pythonfmu3's Python side and the slave need neither (the array output brings its own getter/setter).
    The force equals the force law's."""
    import fmu_bearing.hertz
    from fmu_bearing.ball_bearing import BallBearing

    import ast
    tree = ast.parse(Path(fmu_bearing.hertz.__file__).read_text())
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    if any(m.split(".")[0] in ("scipy", "numpy") for m in imported):
        pytest.skip("fmu_bearing.hertz still imports scipy (which imports numpy): issue 13 item 1, another change")
    result, _ = _no_numpy_host(fmu3, tmp_path, ["numpy", "scipy"])
    assert result.returncode == 0, result.stdout + result.stderr
    lines = dict(line.split(" ", 1) for line in result.stdout.splitlines() if line.startswith(("F ", "MODULES")))
    assert lines["MODULES"].strip() == ""                      # nothing of numpy/scipy was imported
    bearing = BallBearing()
    ref = bearing.evaluate(2.5e-5, -1e-5, 0.0, 0.0, bearing.advance_cage(0.0, 100.0, 0.0, 1e-5), 100.0, 0.0)
    assert tuple(float(x) for x in lines["F"].split()) == (ref.F_x, ref.F_y)


def test_physics_that_cannot_be_imported_fail_instantiation_with_a_message_not_a_crash(fmu3, tmp_path):
    """pythonfmu3 0.3.4 crashes the host when the slave module fails to import; the slave imports its physics
    in a guard and fails the instantiation instead: NULL after a logger message naming the cause, exit 0."""
    unzipped = Path(extract(str(fmu3), unzipdir=str(tmp_path / "probe")))
    packed = sorted(p.name for p in (unzipped / "resources").iterdir() if p.is_dir() and "pythonfmu3" not in p.name
                    and (p / "__init__.py").is_file())   # the (sealed) physics package, not pythonfmu3's copy
    assert packed, "no physics package packed in the FMU"
    result, _ = _no_numpy_host(fmu3, tmp_path, packed)
    assert result.returncode == 1, result.stdout + result.stderr       # our host's assert, not a signal
    assert "instantiate failed" in result.stderr
    assert "LOG 4 " in result.stdout, result.stdout                   # fmi3Fatal, from the logger callback
    logged = result.stdout[result.stdout.index("LOG 4 "):]            # the message spans lines
    assert "cannot import its physics" in logged and "blocked in this host" in logged, logged


SEALED_HOST = r'''
import sys, types
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave
doctored = types.ModuleType("fmu_bearing")          # a host that imported another fmu_bearing
sys.modules["fmu_bearing"] = doctored
path = sys.argv[1]
md = read_model_description(path); d = extract(path)
vr = {v.name: v.valueReference for v in md.modelVariables}
before_path, before_modules = list(sys.path), set(sys.modules)
for rep in range(2):
    instances = []
    for k in range(3):
        s = FMU3Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName=f"b{k}")
        s.instantiate()
        s.enterInitializationMode()
        s.setFloat64([vr[n] for n in ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")],
                     [2.5e-5, -1e-5, 0.0, 0.0, 100.0, 0.0])
        s.exitInitializationMode()
        s.doStep(0.0, 1e-5)
        instances.append(s)
    print("F", *map(repr, instances[-1].getFloat64([vr["F_x"], vr["F_y"]])))
    for s in instances:
        s.terminate()
        s.freeInstance()
    added = sorted(set(sys.modules) - before_modules)
    print("LEFT", rep, sys.path == before_path, sys.modules["fmu_bearing"] is doctored,
          ",".join(m for m in added if m.split(".")[0] not in sys.stdlib_module_names))
'''


def test_sealed_physics_and_sys_path_and_modules_restored_after_free(fmu3, tmp_path):
    """A host that imported another ``fmu_bearing`` still gets the FMU's own physics (packed under a private
    name); after the last fmi3FreeInstance, sys.path and sys.modules are as the FMU found them, and a new
    instance works again (twice, three instances each)."""
    from fmu_bearing.ball_bearing import BallBearing

    result = subprocess.run([sys.executable, "-c", SEALED_HOST, str(fmu3)], capture_output=True, text=True,
                            timeout=120, cwd=str(tmp_path))
    assert result.returncode == 0, result.stdout + result.stderr
    bearing = BallBearing()
    ref = bearing.evaluate(2.5e-5, -1e-5, 0.0, 0.0, bearing.advance_cage(0.0, 100.0, 0.0, 1e-5), 100.0, 0.0)
    forces = [line.split()[1:] for line in result.stdout.splitlines() if line.startswith("F ")]
    assert [tuple(map(float, f)) for f in forces] == [(ref.F_x, ref.F_y)] * 2
    left = [line.split(" ", 4)[1:] for line in result.stdout.splitlines() if line.startswith("LEFT ")]
    assert left == [[str(rep), "True", "True", ""] for rep in range(2)], result.stdout
