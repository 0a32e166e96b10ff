"""The loader's fast path (fmu_bearing/native/loader.c, "fast path") changes no value and no status.

The loader serves fmi2SetReal of the inputs, fmi2DoStep and fmi2GetReal of the force outputs with one
Python call per step (the slave registers ``_fast_step`` at instantiation). Every other call must see the
slave exactly as pythonfmu alone would. Here the same FMU runs twice in this process: through its loader
(the fast path) and through pythonfmu's binary alone (no loader: pythonfmu's path, what the FMU did before),
driven by the same seeded random sequence of FMI calls that interleaves sets and gets of inputs and outputs,
parameter sets (refused after initialisation), non-finite and diverged inputs (refused steps), FMU state
save/restore and serialisation, terminate, reset and a second run; every status and every value must be
the same, bit for bit.
"""
from __future__ import annotations

import ctypes
import math
import random
import struct
import zipfile
from pathlib import Path

import pytest

INPUTS = ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")
COUPLING = ("F_x", "F_y", "stiffness_xx", "stiffness_xy", "stiffness_yy", "damping_xx", "damping_xy",
            "damping_yy", "max_ball_load")
OTHERS = ("cage_angle", "ball_load_1", "ball_load_3", "rating_life", "equivalent_load_inner")
OK, DISCARD = 0, 2


class Raw:
    """An fmpy FMU2Slave driven through its C functions (statuses returned, never raised)."""

    def __init__(self, folder: Path, md, name: str):
        from fmpy.fmi2 import FMU2Slave
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(folder),
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self.dll = self.fmu.dll
        vrs, size, comp = ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t, ctypes.c_void_p
        for name, args in {"fmi2SetReal": [comp, vrs, size, ctypes.POINTER(ctypes.c_double)],
                           "fmi2GetReal": [comp, vrs, size, ctypes.POINTER(ctypes.c_double)],
                           "fmi2SetInteger": [comp, vrs, size, ctypes.POINTER(ctypes.c_int)],
                           "fmi2GetInteger": [comp, vrs, size, ctypes.POINTER(ctypes.c_int)],
                           "fmi2DoStep": [comp, ctypes.c_double, ctypes.c_double, ctypes.c_int],
                           "fmi2Terminate": [comp], "fmi2Reset": [comp],
                           "fmi2GetFMUstate": [comp, ctypes.POINTER(ctypes.c_void_p)],
                           "fmi2SetFMUstate": [comp, ctypes.c_void_p],
                           "fmi2FreeFMUstate": [comp, ctypes.POINTER(ctypes.c_void_p)],
                           "fmi2SerializedFMUstateSize": [comp, ctypes.c_void_p, ctypes.POINTER(ctypes.c_size_t)],
                           "fmi2SerializeFMUstate": [comp, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t],
                           "fmi2DeSerializeFMUstate": [comp, ctypes.c_char_p, ctypes.c_size_t,
                                                       ctypes.POINTER(ctypes.c_void_p)]}.items():
            function = getattr(self.dll, name)
            function.argtypes, function.restype = args, ctypes.c_int
        self.state = None

    def start(self, inputs):
        self.fmu.instantiate(loggingOn=False)
        self.init(inputs)

    def init(self, inputs):
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set_real(list(range(6)), inputs)
        self.fmu.exitInitializationMode()

    def set_real(self, vrs, values):
        return self.dll.fmi2SetReal(self.fmu.component, (ctypes.c_uint * len(vrs))(*vrs), len(vrs),
                                    (ctypes.c_double * len(vrs))(*values))

    def get_real(self, vrs):
        out = (ctypes.c_double * len(vrs))()
        status = self.dll.fmi2GetReal(self.fmu.component, (ctypes.c_uint * len(vrs))(*vrs), len(vrs), out)
        return status, [struct.pack("<d", x) for x in out]   # bits: NaN and -0.0 compare exactly

    def set_integer(self, vrs, values):
        return self.dll.fmi2SetInteger(self.fmu.component, (ctypes.c_uint * len(vrs))(*vrs), len(vrs),
                                       (ctypes.c_int * len(vrs))(*values))

    def get_integer(self, vrs):
        out = (ctypes.c_int * len(vrs))()
        status = self.dll.fmi2GetInteger(self.fmu.component, (ctypes.c_uint * len(vrs))(*vrs), len(vrs), out)
        return status, list(out)

    def do_step(self, t, h):
        return self.dll.fmi2DoStep(self.fmu.component, t, h, 1)

    def save(self):
        if self.state is not None:
            self.dll.fmi2FreeFMUstate(self.fmu.component, ctypes.byref(self.state))
        self.state = ctypes.c_void_p()
        return self.dll.fmi2GetFMUstate(self.fmu.component, ctypes.byref(self.state))

    def restore(self):
        return self.dll.fmi2SetFMUstate(self.fmu.component, self.state)

    def serialize_roundtrip(self):
        """Serialize the saved state, deserialize it and set it: (statuses, size)."""
        size = ctypes.c_size_t()
        s1 = self.dll.fmi2SerializedFMUstateSize(self.fmu.component, self.state, ctypes.byref(size))
        buffer = ctypes.create_string_buffer(size.value)
        s2 = self.dll.fmi2SerializeFMUstate(self.fmu.component, self.state, buffer, size.value)
        copy = ctypes.c_void_p()
        s3 = self.dll.fmi2DeSerializeFMUstate(self.fmu.component, buffer, size.value, ctypes.byref(copy))
        s4 = self.dll.fmi2SetFMUstate(self.fmu.component, copy)
        self.dll.fmi2FreeFMUstate(self.fmu.component, ctypes.byref(copy))
        return (s1, s2, s3, s4), size.value

    def free(self):
        if self.state is not None:
            self.dll.fmi2FreeFMUstate(self.fmu.component, ctypes.byref(self.state))
            self.state = None
        self.fmu.freeInstance()


@pytest.fixture(scope="module")
def model(ball_bearing_fmu):
    from fmpy import read_model_description
    md = read_model_description(str(ball_bearing_fmu))
    return md, {v.name: v.valueReference for v in md.modelVariables}


def _extract(fmu: Path, folder: Path, loader: bool) -> Path:
    with zipfile.ZipFile(fmu) as z:
        z.extractall(folder)
    if not loader:   # pythonfmu's binary alone (a Python host provides libpython): no fast path
        binaries = folder / "binaries" / "linux64"
        for original in binaries.glob("*_pythonfmu.so"):
            original.replace(binaries / original.name.replace("_pythonfmu", ""))
    return folder


@pytest.fixture
def pair(ball_bearing_fmu, model, tmp_path):
    """(fast, slow): the FMU through its loader and through pythonfmu's binary alone."""
    md, _ = model
    fast = Raw(_extract(ball_bearing_fmu, tmp_path / "loader", True), md, "fast")
    slow = Raw(_extract(ball_bearing_fmu, tmp_path / "pythonfmu", False), md, "slow")
    yield fast, slow
    for fmu in (fast, slow):
        try:
            fmu.free()
        except Exception:
            pass


def _fast_path_on(fmu: Raw) -> bool:
    function = fmu.dll.bearingLoaderFastPathOn
    function.argtypes, function.restype = [ctypes.c_void_p], ctypes.c_int
    return bool(function(fmu.fmu.component))


def _inputs(rng):
    e, a = rng.choice((1e-6, 2e-5, 3e-5, 5e-5)), rng.uniform(0.0, 2 * math.pi)
    return [e * math.cos(a), e * math.sin(a), rng.gauss(0.0, 0.02), rng.gauss(0.0, 0.02),
            rng.uniform(-300.0, 300.0), rng.uniform(-50.0, 50.0)]


def _script(rng, vr, n_ops):
    """A random sequence of operations (the same for both FMUs)."""
    ins = [vr[n] for n in INPUTS]
    ops = []
    for _ in range(n_ops):
        kind = rng.choices(("set_all", "set_some", "step", "get_coupling", "get_inputs", "get_mixed", "get_int",
                            "save", "restore", "serialize", "set_param", "set_output", "nan", "diverged"),
                           weights=(10, 5, 14, 8, 4, 4, 2, 1, 1, 1, 1, 1, 1, 1))[0]
        if kind == "set_all":
            ops.append(("set", ins, _inputs(rng)))
        elif kind == "set_some":
            picked = [rng.randrange(6) for _ in range(rng.randint(1, 4))]   # duplicates too: the last wins
            values = _inputs(rng)
            ops.append(("set", [ins[k] for k in picked], [values[k] for k in picked]))
        elif kind == "get_coupling":
            names = rng.sample(COUPLING, rng.randint(1, len(COUPLING)))
            ops.append(("get", [vr[n] for n in names]))
        elif kind == "get_inputs":
            ops.append(("get", [ins[k] for k in rng.sample(range(6), rng.randint(1, 6))]))
        elif kind == "get_mixed":
            names = rng.sample(COUPLING + INPUTS + OTHERS, 5)
            ops.append(("get", [vr[n] for n in names]))
        elif kind == "get_int":
            ops.append(("get_int", [vr["loaded_balls"], vr["n_balls"]]))
        elif kind == "set_param":
            ops.append(rng.choice((("set", [vr["radial_clearance"]], [1e-5]),
                                   ("set_int", [vr["n_balls"]], [9]))))
        elif kind == "set_output":
            ops.append(("set", [ins[0], vr["F_x"]], [1e-5, 5.0]))   # F_x refused, e_x set
        elif kind == "nan":
            ops.append(("set", [ins[rng.randrange(6)]], [rng.choice((math.nan, math.inf, -math.inf))]))
        elif kind == "diverged":
            ops.append(("set", ins[:2], [1.0, 0.0]))
        else:
            ops.append((kind,))
    return ops


def _run(fmu: Raw, ops, vr, record):
    t, h = 0.0, 1e-5
    saved = False
    for op in ops:
        kind = op[0]
        if kind == "set":
            record.append((kind, fmu.set_real(op[1], op[2])))
        elif kind == "set_int":
            record.append((kind, fmu.set_integer(op[1], op[2])))
        elif kind == "get":
            record.append((kind, op[1], fmu.get_real(op[1])))
        elif kind == "get_int":
            record.append((kind, fmu.get_integer(op[1])))
        elif kind == "step":
            status = fmu.do_step(t, h)
            record.append((kind, t, status))
            if status == OK:
                t += h
        elif kind == "save":
            record.append((kind, fmu.save()))
            saved = True
        elif kind == "restore" and saved:
            record.append((kind, fmu.restore()))
        elif kind == "serialize" and saved:
            record.append((kind, fmu.serialize_roundtrip()))
    outputs = [vr[n] for n in INPUTS + COUPLING + OTHERS]
    record.append(("end", fmu.get_real(outputs), fmu.get_integer([vr["loaded_balls"]])))
    return t


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_fast_path_gives_what_pythonfmu_gives(pair, model, seed):
    _, vr = model
    fast, slow = pair
    rng = random.Random(seed)
    start = _inputs(rng)
    ops = _script(rng, vr, 600)
    records = []
    for fmu in (fast, slow):
        record = []
        fmu.start(start)
        if fmu is fast:
            assert _fast_path_on(fast), "the slave did not register its step with the loader"
        t = _run(fmu, ops, vr, record)
        # after fmi2Terminate: steps refused, values readable; the fast path is off
        record.append(("terminate", fmu.dll.fmi2Terminate(fmu.fmu.component)))
        if fmu is fast:
            assert not _fast_path_on(fast)
        record.append(("step after terminate", fmu.do_step(t, 1e-5)))
        record.append(("get after terminate", fmu.get_real([vr[n] for n in INPUTS + COUPLING])))
        # fmi2Reset: a new slave, which registers again; a second run from the start
        record.append(("reset", fmu.dll.fmi2Reset(fmu.fmu.component)))
        fmu.state = None   # states of the old slave are not used after a reset
        fmu.init(start)
        if fmu is fast:
            assert _fast_path_on(fast), "the slave built by fmi2Reset did not register"
        _run(fmu, ops[:150], vr, record)
        records.append(record)
    fast_record, slow_record = records
    assert len(fast_record) == len(slow_record)
    for a, b in zip(fast_record, slow_record):
        assert a == b
    statuses = [r[-1] for r in fast_record if r[0] == "step"]
    assert statuses.count(OK) > 100 and DISCARD in statuses, "the script must step and be refused"


def test_fast_path_matches_pythonfmu_on_the_plain_exchange(pair, model):
    """The master's exchange (set 6 inputs, doStep, get the coupling outputs) over 2,000 steps."""
    _, vr = model
    fast, slow = pair
    rng = random.Random(7)
    start = _inputs(rng)
    ins, outs = [vr[n] for n in INPUTS], [vr[n] for n in COUPLING]
    for fmu in (fast, slow):
        fmu.start(start)
    for i in range(2000):
        u = _inputs(rng)
        got = []
        for fmu in (fast, slow):
            got.append((fmu.set_real(ins, u), fmu.do_step(i * 1e-5, 1e-5), fmu.get_real(outs)))
        assert got[0] == got[1], i
    assert _fast_path_on(fast)


def test_refused_step_message_reaches_the_host(ball_bearing_fmu, model, tmp_path, capsys):
    """A step refused on the fast path still sends its error to the host (fmpy's default logger prints it)."""
    md, vr = model
    fast = Raw(_extract(ball_bearing_fmu, tmp_path / "loader", True), md, "fast")
    try:
        fast.start([1e-5, 0.0, 0.0, 0.0, 100.0, 0.0])
        assert _fast_path_on(fast)
        capsys.readouterr()
        assert fast.set_real([vr["e_y"]], [math.nan]) == OK
        assert fast.do_step(0.0, 1e-5) == DISCARD
        out = capsys.readouterr().out
        assert "e_y" in out and "not a finite number" in out, out
    finally:
        fast.free()
