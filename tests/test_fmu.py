"""The BUILT BallBearing FMU through fmpy: modelDescription, simulate_fmu, FMU2Slave against the in-process
force law, FMU state, several instances, capacities, and the error paths (status and logger message)."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
import zipfile
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave)
from mechanism.cosim.fmpy_logging import fmpy_callbacks
from fmpy.validation import validate_fmu

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import BearingParameters

ROOT = Path(__file__).resolve().parent.parent
TABLE2 = BearingParameters()
HALF = TABLE2.radial_clearance / 2
INPUTS = ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")
REAL_OUTPUTS = ("F_x", "F_y", "stiffness_xx", "stiffness_xy", "stiffness_yy",
                "damping_xx", "damping_xy", "damping_yy", "max_ball_load", "cage_angle")
DISCARD = 2


class FMU:
    """An extracted FMU and its model description."""

    def __init__(self, path: Path, unzipdir: Path):
        self.path = path
        self.md = read_model_description(str(path))
        self.dir = str(unzipdir)
        self.var = {v.name: v for v in self.md.modelVariables}
        self.vr = {n: v.valueReference for n, v in self.var.items()}
        self.capacity = sum(1 for n in self.var if n.startswith("ball_load_"))


@pytest.fixture(scope="module")
def fmu(ball_bearing_fmu, tmp_path_factory) -> FMU:
    d = tmp_path_factory.mktemp("unzipped")
    return FMU(ball_bearing_fmu, Path(extract(str(ball_bearing_fmu), unzipdir=str(d))))


class Instance:
    """One FMU2Slave instance with its own logger callback, start values and initialisation."""

    def __init__(self, fmu: FMU, name="bearing", params=None, inputs=None, logging_on=True, initialise=True):
        self.fmu, self.messages = fmu, []
        self.params = dict(params or {})
        self.callbacks = fmpy_callbacks(self._log)  # fmpy's proxy formats the message; never dangles
        self.s = FMU2Slave(guid=fmu.md.guid, unzipDirectory=fmu.dir,
                           modelIdentifier=fmu.md.coSimulation.modelIdentifier, instanceName=name)
        self.s.instantiate(callbacks=self.callbacks, loggingOn=logging_on)
        self.s.setupExperiment(startTime=0.0)
        self.s.enterInitializationMode()
        for k, value in self.params.items():
            self.set(k, value)
        if inputs is not None:
            self.set_inputs(inputs)
        if initialise:
            self.s.exitInitializationMode()
        self.real_vrs = [fmu.vr[n] for n in REAL_OUTPUTS] + [fmu.vr[f"ball_load_{k + 1}"]
                                                            for k in range(fmu.capacity)]

    def _log(self, env, instance, status, category, message):
        self.messages.append((status, message.decode("utf-8", "replace")))

    def set(self, name, value):
        t = self.fmu.var[name].type
        if t == "Integer":
            self.s.setInteger([self.fmu.vr[name]], [int(value)])
        elif t == "Boolean":
            self.s.setBoolean([self.fmu.vr[name]], [bool(value)])
        else:
            self.s.setReal([self.fmu.vr[name]], [float(value)])

    def set_inputs(self, values):
        self.s.setReal([self.fmu.vr[n] for n in INPUTS], [float(x) for x in values])

    def outputs(self) -> np.ndarray:
        """All Real outputs (REAL_OUTPUTS, then ball loads) and loaded_balls last."""
        real = self.s.getReal(self.real_vrs)
        return np.array(real + [float(self.s.getInteger([self.fmu.vr["loaded_balls"]])[0])])

    def free(self):
        self.s.terminate()
        self.s.freeInstance()


class Model:
    """The in-process force law with the FMU's step semantics (advance the cage, then evaluate)."""

    def __init__(self, params: dict, capacity: int):
        self.b = BallBearing(TABLE2.replace(**params), capacity)
        self.capacity = capacity
        self.cage = self.b.params.cage_angle_start
        self.inputs = (0.0,) * 6

    def start(self, inputs):
        self.inputs = tuple(inputs)
        return self._out()

    def step(self, h, inputs):
        self.inputs = tuple(inputs)
        self.cage = self.b.advance_cage(self.cage, self.inputs[4], self.inputs[5], h)
        return self._out()

    def _out(self):
        ex, ey, vx, vy, wi, wo = self.inputs
        loads = [0.0] * self.capacity
        r = self.b.evaluate(ex, ey, vx, vy, self.cage, wi, wo, loads)
        return np.array([r.F_x, r.F_y, r.k_xx, r.k_xy, r.k_yy, r.c_xx, r.c_xy, r.c_yy, r.max_ball_load,
                         self.cage, *loads, float(r.loaded_balls)])


def random_inputs(rng):
    a = rng.uniform(0, 2 * math.pi)
    if rng.uniform() < 0.2:
        radius = rng.uniform(0, HALF)                  # inside the clearance
    else:
        radius = rng.uniform(HALF, 8e-5)
    return (radius * math.cos(a), radius * math.sin(a), *rng.normal(0, 0.02, 2), *rng.normal(0, 200, 2))


def reference_force(e, cage, K, n, half):
    """Eq. (18)-(19) without damping, written out with numpy: sum_r K (e . u_r - P_d/2)_+^1.5 u_r."""
    phi = cage + 2 * np.pi * np.arange(n) / n
    u = np.stack([np.cos(phi), np.sin(phi)])
    delta = np.clip(np.asarray(e) @ u - half, 0, None)
    return (K * delta ** 1.5 * u).sum(axis=1)


# --- modelDescription --------------------------------------------------------------------------

def test_validate_fmu_finds_no_problems(fmu):
    assert validate_fmu(str(fmu.path)) == []


def test_model_description_declares_interface_units_and_capabilities(fmu):
    md = fmu.md
    assert md.modelName == "BallBearing" and md.fmiVersion == "2.0"
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    assert float(md.defaultExperiment.stopTime) == 0.1 and float(md.defaultExperiment.stepSize) == 1e-5
    units = {u.name: u for u in md.unitDefinitions}
    assert units["N"].baseUnit.kg == 1 and units["N"].baseUnit.m == 1 and units["N"].baseUnit.s == -2
    assert units["N/m"].baseUnit.kg == 1 and units["N/m"].baseUnit.s == -2
    assert units["N.s/m"].baseUnit.kg == 1 and units["N.s/m"].baseUnit.s == -1
    assert units["rad/s"].baseUnit.rad == 1 and units["rad/s"].baseUnit.s == -1
    for v in md.modelVariables:
        assert v.description, v.name
        if v.type == "Real":
            assert v.unit in units, v.name
    expected_units = {"e_x": "m", "v_y": "m/s", "omega_inner": "rad/s", "F_x": "N", "stiffness_xy": "N/m",
                      "damping_yy": "N.s/m", "cage_angle": "rad", "ball_load_20": "N", "max_ball_load": "N",
                      "youngs_modulus": "Pa", "oil_viscosity": "Pa.s", "radial_clearance": "m"}
    for name, unit in expected_units.items():
        assert fmu.var[name].unit == unit, name
    for name in INPUTS:
        v = fmu.var[name]
        assert (v.causality, v.variability, v.type, float(v.start)) == ("input", "continuous", "Real", 0.0)
    for name in REAL_OUTPUTS + ("loaded_balls", "ball_load_1"):   # computed in fmi2ExitInitializationMode
        assert fmu.var[name].causality == "output" and fmu.var[name].initial == "calculated"
        assert fmu.var[name].start is None
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    assert [u.variable for u in md.initialUnknowns] == outputs
    assert fmu.var["loaded_balls"].type == "Integer"
    assert fmu.capacity == 20 and "ball_load_21" not in fmu.var
    # one parameter per BearingParameters field, with its default
    params = [v for v in md.modelVariables if v.causality == "parameter"]
    assert [v.name for v in params] == [f.name for f in fields(BearingParameters)]
    for f in fields(BearingParameters):
        v = fmu.var[f.name]
        assert v.variability == "fixed"
        if isinstance(f.default, bool):
            assert v.type == "Boolean" and str(v.start).lower() == str(f.default).lower()
        elif isinstance(f.default, int):
            assert v.type == "Integer" and int(v.start) == f.default
        else:
            assert v.type == "Real" and float(v.start) == f.default
    assert int(fmu.var["n_balls"].min) == 3 and int(fmu.var["n_balls"].max) == 20
    assert {s.variable.name for s in md.outputs} == {v.name for v in md.modelVariables if v.causality == "output"}


# --- simulate_fmu ------------------------------------------------------------------------------

def test_simulate_fmu_with_an_input_array(fmu):
    e, w_i = (2.2e-5, -0.6e-5), 150.0
    t = np.array([0.0, 0.01])
    signals = np.zeros(2, dtype=[("time", float)] + [(n, float) for n in INPUTS])
    signals["time"] = t
    signals["e_x"], signals["e_y"], signals["omega_inner"] = e[0], e[1], w_i
    result = simulate_fmu(str(fmu.path), start_time=0.0, stop_time=0.002, step_size=1e-4, output_interval=1e-4,
                          input=signals, start_values={"damping_model": 0},
                          output=["F_x", "F_y", "cage_angle", "loaded_balls"])
    assert len(result) == 21
    K = BallBearing(TABLE2).stiffness
    # eq. (16) with omega_outer = 0: omega_m = omega_i d_i / (d_i + d_o), Table 2 diameters
    omega_m = w_i * 29.2 / (29.2 + 46.6)
    np.testing.assert_allclose(result["cage_angle"], omega_m * result["time"], rtol=1e-12, atol=1e-15)
    for row in result:
        F = reference_force(e, row["cage_angle"], K, 8, HALF)
        np.testing.assert_allclose([row["F_x"], row["F_y"]], F, rtol=1e-9, atol=1e-9 * np.abs(F).max())
        assert row["loaded_balls"] >= 1


# --- FMU2Slave against the in-process force law -------------------------------------------------

CASES = {
    "table2": {},
    "oil-film-12": {"n_balls": 12, "damping_model": 2, "cage_angle_start": 0.7},
    "20-balls-no-damping": {"n_balls": 20, "allow_ball_overlap": True, "damping_model": 0,
                            "radial_clearance": 10e-6},
}


@pytest.mark.parametrize("case", CASES)
def test_outputs_equal_the_in_process_force_law(fmu, case):
    rng = np.random.default_rng(10)
    start = random_inputs(rng)
    inst = Instance(fmu, params=CASES[case], inputs=start)
    model = Model(CASES[case], fmu.capacity)
    try:
        np.testing.assert_allclose(inst.outputs(), model.start(start), rtol=1e-12, atol=0)
        t = 0.0
        for _ in range(200):
            u, h = random_inputs(rng), rng.uniform(1e-6, 1e-3)
            inst.set_inputs(u)
            inst.s.doStep(t, h)
            t += h
            np.testing.assert_allclose(inst.outputs(), model.step(h, u), rtol=1e-12, atol=0)
        assert inst.messages == []
    finally:
        inst.free()


@pytest.mark.parametrize("n_balls", [5, 15, 20])
def test_n_balls_up_to_the_capacity_and_absent_balls_read_zero(fmu, n_balls):
    params = {"n_balls": n_balls, "allow_ball_overlap": True}
    inst = Instance(fmu, params=params, inputs=(0.0,) * 6)
    model = Model(params, fmu.capacity)
    rng = np.random.default_rng(n_balls)
    try:
        for k in range(50):
            u = random_inputs(rng)
            inst.set_inputs(u)
            inst.s.doStep(k * 1e-4, 1e-4)
            out = inst.outputs()
            np.testing.assert_allclose(out, model.step(1e-4, u), rtol=1e-12, atol=0)
            loads = out[len(REAL_OUTPUTS):len(REAL_OUTPUTS) + fmu.capacity]
            assert np.all(loads[n_balls:] == 0.0)
            assert out[-1] == np.count_nonzero(loads[:n_balls])
    finally:
        inst.free()


def test_three_instances_in_one_process_stay_independent(fmu):
    cases = [{}, {"n_balls": 12, "damping_model": 2, "radial_clearance": 10e-6},
             {"n_balls": 15, "allow_ball_overlap": True, "damping_model": 0, "cage_angle_start": 0.4}]
    rng = np.random.default_rng(11)
    insts = [Instance(fmu, name=f"bearing{i}", params=c, inputs=(0.0,) * 6) for i, c in enumerate(cases)]
    models = [Model(c, fmu.capacity) for c in cases]
    try:
        t = 0.0
        for _ in range(60):
            h = 2e-5
            order = rng.permutation(3)
            inputs = {}
            for i in order:                       # interleaved: set all, then step all, then read all
                inputs[i] = random_inputs(rng)
                insts[i].set_inputs(inputs[i])
            for i in order[::-1]:
                insts[i].s.doStep(t, h)
            for i in order:
                np.testing.assert_allclose(insts[i].outputs(), models[i].step(h, inputs[i]), rtol=1e-12, atol=0)
            t += h
    finally:
        for inst in insts:
            inst.free()


# --- FMU state ---------------------------------------------------------------------------------

def test_a_state_saved_before_initialisation_gets_the_complete_check_after_it(fmu):
    """fmi2SetFMUstate restores the instance's own in-memory states without re-checking them only when they
    were saved since its initialisation (the masters' rollback); a state saved before it, with other
    parameters, is still refused (parameters are fixed after initialisation), and nothing is assigned."""
    inst = Instance(fmu, params={"n_balls": 8}, inputs=(2e-5, 0.0, 1e-3, 0.0, 125.0, 0.0), initialise=False)
    try:
        before = inst.s.getFMUstate()                    # n_balls = 8, not initialised
        inst.set("n_balls", 9)
        inst.s.exitInitializationMode()
        inst.s.doStep(0.0, 1e-5)
        now = inst.outputs()
        inst.s.setFMUstate(before)
        assert "n_balls" in inst.messages[-1][1] and "refused" in inst.messages[-1][1], inst.messages[-1]
        np.testing.assert_array_equal(inst.outputs(), now)
        with pytest.raises(FMICallException):
            inst.s.doStep(1e-5, 1e-5)                    # the refusal is reported by the next step
        own = inst.s.getFMUstate()                       # saved since initialisation: restored at once
        inst.set_inputs((3e-5, 0.0, 0.0, 0.0, 125.0, 0.0))
        inst.s.doStep(1e-5, 1e-5)
        inst.s.setFMUstate(own)
        np.testing.assert_array_equal(inst.outputs(), now)
        inst.s.freeFMUstate(own)
        inst.s.freeFMUstate(before)
    finally:
        inst.free()


def test_state_get_set_and_serialize_round_trip(fmu):
    params = {"damping_model": 2, "n_balls": 9}
    rng = np.random.default_rng(12)
    inst = Instance(fmu, params=params, inputs=random_inputs(rng))
    other = Instance(fmu, name="other", params=params, inputs=(0.0,) * 6)
    try:
        t = 0.0
        for _ in range(10):
            inst.set_inputs(random_inputs(rng))
            inst.s.doStep(t, 1e-4)
            t += 1e-4
        saved_outputs, saved_t = inst.outputs(), t
        state = inst.s.getFMUstate()
        inputs = [random_inputs(rng) for _ in range(6)]

        def run_from_saved(instance):
            trace, tt = [], saved_t
            instance.s.doStep(tt, 1e-4)           # first step with the saved (held) inputs
            trace.append(instance.outputs())
            tt += 1e-4
            for u in inputs:
                instance.set_inputs(u)
                instance.s.doStep(tt, 1e-4)
                tt += 1e-4
                trace.append(instance.outputs())
            return np.array(trace)

        reference = run_from_saved(inst)
        # restore: outputs, cage angle and inputs come back
        inst.set_inputs(random_inputs(rng))
        inst.s.setFMUstate(state)
        np.testing.assert_array_equal(inst.outputs(), saved_outputs)
        np.testing.assert_array_equal(run_from_saved(inst), reference)
        # serialize / deserialize, into the same and into another instance
        blob = inst.s.serializeFMUstate(state)
        assert isinstance(blob, bytes) and len(blob) > 0
        state2 = inst.s.deSerializeFMUstate(blob)
        inst.s.setFMUstate(state2)
        np.testing.assert_array_equal(run_from_saved(inst), reference)
        state3 = other.s.deSerializeFMUstate(blob)
        other.s.setFMUstate(state3)
        np.testing.assert_array_equal(other.outputs(), saved_outputs)
        np.testing.assert_array_equal(run_from_saved(other), reference)
        for s, owner in ((state, inst), (state2, inst), (state3, other)):
            owner.s.freeFMUstate(s)
    finally:
        inst.free()
        other.free()


# --- errors ------------------------------------------------------------------------------------

@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")], ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize("name", INPUTS)
def test_non_finite_input_makes_do_step_fail_with_a_message(fmu, name, bad):
    good = (1.5e-5, 0.3e-5, 0.01, 0.0, 100.0, 0.0)
    inst = Instance(fmu, inputs=good)
    try:
        inst.s.doStep(0.0, 1e-4)
        before = inst.outputs()
        inst.set(name, bad)
        with pytest.raises(FMICallException) as err:
            inst.s.doStep(1e-4, 1e-4)
        assert err.value.status >= DISCARD
        errors = [m for s, m in inst.messages if s >= 3]
        assert errors and name in errors[-1] and "not a finite number" in errors[-1]
        after = inst.outputs()
        assert np.all(np.isfinite(after))
        np.testing.assert_array_equal(after, before)     # the refused step changed nothing
        inst.set(name, good[INPUTS.index(name)])             # and the instance recovers
        inst.s.doStep(1e-4, 1e-4)
        assert np.all(np.isfinite(inst.outputs()))
    finally:
        inst.free()                                       # can still be terminated and freed


@pytest.mark.parametrize("params, e_x", [({}, 5e-4), ({"eccentricity_limit": 1e-4}, 1.2e-4)])
def test_eccentricity_beyond_the_limit_is_an_error(fmu, params, e_x):
    inst = Instance(fmu, params=params, inputs=(1e-5, 0, 0, 0, 0, 0))
    try:
        inst.set("e_x", e_x)
        with pytest.raises(FMICallException) as err:
            inst.s.doStep(0.0, 1e-4)
        assert err.value.status >= DISCARD
        message = [m for s, m in inst.messages if s >= 3][-1]
        assert "exceeds eccentricity_limit" in message and f"|e| = {e_x:.6g} m" in message
    finally:
        inst.free()


INVALID = [("n_balls", 2), ("n_balls", 21), ("poisson_ratio", 0.7), ("youngs_modulus", -1e9),
           ("radial_clearance", -1e-4), ("reliability_factor", 2.0), ("inner_groove_conformity", 0.5), ("damping_coefficient", -5.0),
           ("inner_race_diameter", 0.03), ("n_balls", 14)]


@pytest.mark.parametrize("name, value", INVALID, ids=[f"{n}={v}" for n, v in INVALID])
def test_invalid_parameter_fails_initialisation_naming_it(fmu, name, value):
    inst = Instance(fmu, params={name: value}, initialise=False)
    try:
        with pytest.raises(FMICallException) as err:
            inst.s.exitInitializationMode()
        assert err.value.function == "fmi2ExitInitializationMode" and err.value.status >= 3
        errors = [m for s, m in inst.messages if s >= 3]
        assert any(f"{name} = {value!r}" in m for m in errors), errors
        with pytest.raises(FMICallException):               # a failed instance refuses to step ...
            inst.s.doStep(0.0, 1e-4)
    finally:
        inst.s.freeInstance()                               # ... and can be freed


def test_start_inputs_beyond_the_limit_fail_initialisation(fmu):
    inst = Instance(fmu, inputs=(1e-3, 0, 0, 0, 0, 0), initialise=False)
    try:
        with pytest.raises(FMICallException):
            inst.s.exitInitializationMode()
        assert any("eccentricity" in m for s, m in inst.messages if s >= 3)
    finally:
        inst.s.freeInstance()


def test_setting_a_fixed_parameter_after_initialisation_is_refused(fmu):
    inst = Instance(fmu, inputs=(2e-5, 0, 0, 0, 0, 0))
    model = Model({}, fmu.capacity)
    model.start((2e-5, 0, 0, 0, 0, 0))
    try:
        inst.set("damping_coefficient", 1.0)
        with pytest.raises(FMICallException):
            inst.s.doStep(0.0, 1e-4)
        assert any("damping_coefficient is fixed" in m for s, m in inst.messages if s >= 3)
        u = (2e-5, 0, 0.01, 0, 0, 0)
        inst.set_inputs(u)
        inst.s.doStep(0.0, 1e-4)                            # the next step runs, with the old value
        np.testing.assert_allclose(inst.outputs(), model.step(1e-4, u), rtol=1e-12, atol=0)
    finally:
        inst.free()


# --- builds ------------------------------------------------------------------------------------

def test_build_with_max_balls_32(fmu, tmp_path):
    proc = subprocess.run([sys.executable, str(ROOT / "build_fmu.py"), "--max-balls", "32", "--out", str(tmp_path),
                           "--only", "BallBearing"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    path = tmp_path / "BallBearing.fmu"
    assert "BallBearing.fmu" in proc.stdout and path.is_file()
    assert validate_fmu(str(path)) == []
    big = FMU(path, Path(extract(str(path), unzipdir=str(tmp_path / "x"))))
    assert big.capacity == 32 and "ball_load_32" in big.var and "ball_load_33" not in big.var
    assert int(big.var["n_balls"].max) == 32
    for name in INPUTS + REAL_OUTPUTS + ("n_balls", "loaded_balls"):  # capacity does not move the others
        assert big.vr[name] == fmu.vr[name]
    params = {"n_balls": 32, "allow_ball_overlap": True}
    inst = Instance(big, params=params, inputs=(0.0,) * 6)
    model = Model(params, 32)
    try:
        u = (6e-5, 1e-5, 0.0, 0.0, 50.0, 0.0)
        inst.set_inputs(u)
        inst.s.doStep(0.0, 1e-4)
        out = inst.outputs()
        np.testing.assert_allclose(out, model.step(1e-4, u), rtol=1e-12, atol=0)
        assert out[-1] > 8
    finally:
        inst.free()


def test_fmu_runs_without_the_project_installed(fmu, tmp_path):
    """In a fresh interpreter that may not import the project from outside the FMU, it still runs."""
    unzipdir = tmp_path / "fmu"
    script = textwrap.dedent(f"""
        import importlib.machinery, json, sys
        UNZIP = {str(unzipdir)!r}
        class Guard:  # the project's modules may only come from inside the extracted FMU
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in ("fmu_bearing", "ball_bearing_fmu", "build_fmu", "mechanism"):
                    spec = importlib.machinery.PathFinder.find_spec(name, path)
                    if spec is None or not str(spec.origin).startswith(UNZIP):
                        raise ImportError(name + " would be imported from outside the FMU")
                    return spec
                return None
        sys.meta_path.insert(0, Guard())
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        extract({str(fmu.path)!r}, unzipdir=UNZIP)
        md = read_model_description(UNZIP)
        vr = {{v.name: v.valueReference for v in md.modelVariables}}
        s = FMU2Slave(guid=md.guid, unzipDirectory=UNZIP, modelIdentifier="BallBearing", instanceName="x")
        s.instantiate(); s.setupExperiment(startTime=0.0); s.enterInitializationMode()
        s.setReal([vr["e_x"]], [2e-5]); s.exitInitializationMode(); s.doStep(0.0, 1e-4)
        F = s.getReal([vr["F_x"], vr["F_y"]])
        s.terminate(); s.freeInstance()
        print(json.dumps({{"F": F, "modules": {{name: getattr(m, "__file__", None) for name, m in sys.modules.items()
                                              if "fmu_bearing" in name or "pythonfmu" in name}}}}))
    """)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["modules"] == {}  # freed: the FMU's (privately named) modules have left sys.modules
    K = BallBearing(TABLE2).stiffness
    expected = reference_force((2e-5, 0.0), 0.0, K, 8, HALF)
    np.testing.assert_allclose(result["F"], expected, rtol=1e-9, atol=1e-9 * abs(expected[0]))


def test_fmu_packs_the_package_and_build_options(fmu):
    with zipfile.ZipFile(fmu.path) as z:
        names = set(z.namelist())
        options = json.loads(z.read("resources/build_options.json"))
        slave = z.read("resources/slavemodule.txt").decode()
    # sealed (build_fmu.seal): packages and slave module under private names unique to the build
    tag = slave.rsplit("_", 1)[1]
    assert len(tag) == 12 and slave == f"ball_bearing_fmu_{tag}"
    import build_fmu
    spec = next(s for s in build_fmu.REGISTRY if s.name == "BallBearing")
    assert options == {"max_balls": 20, "sources_sha256": build_fmu.source_digest(spec),
                       "private_modules": [f"_fmu_bearing_{tag}", f"_pythonfmu_{tag}", slave]}
    for required in (f"resources/{slave}.py", f"resources/_fmu_bearing_{tag}/__init__.py",
                     f"resources/_fmu_bearing_{tag}/ball_bearing.py", f"resources/_fmu_bearing_{tag}/hertz.py",
                     f"resources/_fmu_bearing_{tag}/parameters.py", f"resources/_pythonfmu_{tag}/fmi2slave.py",
                     "binaries/linux64/BallBearing.so"):
        assert required in names
    assert not any(n.startswith(("resources/fmu_bearing/", "resources/pythonfmu/")) for n in names)
    assert not any("__pycache__" in n or n.endswith(".pyc") for n in names)


def test_many_failed_initialisations_leave_the_host_process_intact(fmu, tmp_path):
    """pythonfmu 0.7 over-releases Python objects when an exception fails a call; repeated failed
    initialisations used to crash the host a few failures later (see fmu_bearing.slaves.hold_before_raise).
    The failed slaves are kept alive, but their imports are undone: after the last free, sys.path and the
    FMU's modules in sys.modules are as before the first instance (issue 13)."""
    script = textwrap.dedent(f"""
        import gc, sys
        from fmpy import extract, read_model_description
        from fmpy.fmi1 import FMICallException
        from fmpy.fmi2 import FMU2Slave
        d = str(extract({str(fmu.path)!r}, unzipdir={str(tmp_path / "x")!r}))
        md = read_model_description(d)
        vr = {{v.name: v.valueReference for v in md.modelVariables}}
        path, modules = list(sys.path), set(sys.modules)
        def instance(name):
            s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier="BallBearing", instanceName=name)
            s.instantiate(); s.setupExperiment(startTime=0.0); s.enterInitializationMode()
            return s
        for i in range(40):
            s = instance(f"bad{{i}}")
            s.setInteger([vr["n_balls"]], [2])
            try:
                s.exitInitializationMode()
                raise SystemExit("initialisation did not fail")
            except FMICallException:
                pass
            try:
                s.doStep(0.0, 1e-4)
                raise SystemExit("a failed instance stepped")
            except FMICallException:
                pass
            s.terminate(); s.freeInstance()
            gc.collect()
        s = instance("good")
        s.setReal([vr["e_x"]], [2e-5]); s.exitInitializationMode()
        for k in range(200):
            s.doStep(k * 1e-4, 1e-4)
        x = [dict(a=i) for i in range(100000)]; gc.collect()
        F = s.getReal([vr["F_x"]])[0]
        s.terminate(); s.freeInstance()
        left = [m for m in set(sys.modules) - modules if str(getattr(sys.modules[m], "__file__", "")).startswith(d)]
        print(F, sys.path == path, left)
    """)
    proc = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    F, restored, left = proc.stdout.strip().splitlines()[-1].split(" ", 2)
    assert float(F) > 0 and restored == "True" and left == "[]"
