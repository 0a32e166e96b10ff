"""The loader's C step (fmu_bearing/native/loader.c, "C step") gives the Python step's doubles, bit for bit.

With the C step the loader does the whole BallBearing doStep in C (damping_model 0 and 1) and pushes its state
into the Python slave before any call it forwards. Here the same FMU runs side by side in this process:
  * "c":      through its loader with the C step (the default);
  * "python": through pythonfmu's binary alone (no loader: the Python step, what the FMU did before).
Both get the same calls; every status, every value (compared as bits: NaN and -0.0 too) and every message to
the host must be the same. The loader's step counter (bearingLoaderKernelSteps) proves that the C step ran, and
BEARING_FMU_C_STEP=0 that the switch turns it off. A whole master run must write the same CSV either way.
"""
from __future__ import annotations

import ctypes
import filecmp
import math
import os
import random
import subprocess
import sys
from pathlib import Path

import pytest

from test_loader_fastpath import COUPLING, INPUTS, OK, Raw, _extract, _inputs, _run, _script

ROOT = Path(__file__).resolve().parents[1]
DISCARD = 2


@pytest.fixture(scope="module")
def model(ball_bearing_fmu):
    from fmpy import read_model_description
    md = read_model_description(str(ball_bearing_fmu))
    return md, {v.name: v.valueReference for v in md.modelVariables}, md.modelVariables


class Pair:
    """The FMU with the C step (``c``) and through pythonfmu alone (``python``), driven with the same calls."""

    def __init__(self, fmu, md, tmp_path, kernel="1"):
        self.allow_overlap = next(v.valueReference for v in md.modelVariables if v.name == "allow_ball_overlap")
        self.c = Raw(_extract(fmu, tmp_path / "loader", True), md, "bearing")
        self.python = Raw(_extract(fmu, tmp_path / "pythonfmu", False), md, "bearing")
        self.kernel = kernel

    def both(self):
        return self.c, self.python

    def start(self, inputs, ints=(), reals=()):
        """Instantiate both (the C step switched by BEARING_FMU_C_STEP = ``kernel`` at instantiation) with
        the parameters ``ints`` / ``reals`` ((vr, value) pairs) and initialise them at ``inputs``."""
        for fmu in self.both():
            old = os.environ.get("BEARING_FMU_C_STEP")
            os.environ["BEARING_FMU_C_STEP"] = self.kernel
            try:
                fmu.fmu.instantiate(loggingOn=False)
            finally:
                if old is None:
                    del os.environ["BEARING_FMU_C_STEP"]
                else:
                    os.environ["BEARING_FMU_C_STEP"] = old
            fmu.fmu.setupExperiment(startTime=0.0)
            fmu.fmu.enterInitializationMode()
            for vr, value in ints:
                assert fmu.set_integer([vr], [value]) == OK
            if ints:   # the paper's 15- and 20-ball studies: more balls than fit the default geometry
                fmu.fmu.setBoolean([self.allow_overlap], [True])
            for vr, value in reals:
                assert fmu.set_real([vr], [value]) == OK
            assert fmu.set_real(list(range(6)), inputs) == OK
            fmu.fmu.exitInitializationMode()

    def kernel_steps(self) -> int:
        function = self.c.dll.bearingLoaderKernelSteps
        function.argtypes, function.restype = [ctypes.c_void_p], ctypes.c_longlong
        return function(self.c.fmu.component)

    def free(self):
        for fmu in self.both():
            try:
                fmu.free()
            except Exception:
                pass


@pytest.fixture
def pair(ball_bearing_fmu, model, tmp_path):
    md, _, _ = model
    p = Pair(ball_bearing_fmu, md, tmp_path)
    yield p
    p.free()


def _same(pair, capsys, call):
    """call(fmu) on both FMUs; the results and what reached the host's logger (stdout) must be the same."""
    got = []
    for fmu in pair.both():
        capsys.readouterr()
        result = call(fmu)
        got.append((result, capsys.readouterr().out))
    assert got[0] == got[1]
    return got[0][0]


def _real_vrs(variables):
    return [v.valueReference for v in variables if v.type == "Real"]


@pytest.mark.parametrize("n_balls", [8, 15, 20])
@pytest.mark.parametrize("damping", [(0, 50.0), (1, 0.0), (1, 50.0)], ids=["none", "C0", "C50"])
def test_c_step_equals_python_step_bit_for_bit(pair, model, capsys, n_balls, damping):
    """Random inputs in and out of the load zone, random step sizes; every output after every step; now and
    then every Real variable (life outputs too: that read makes the loader push the C step's state)."""
    _, vr, variables = model
    model_, coefficient = damping
    rng = random.Random(1000 * n_balls + 10 * model_ + int(coefficient))
    pair.start(_inputs(rng), ints=[(vr["n_balls"], n_balls), (vr["damping_model"], model_)],
               reals=[(vr["damping_coefficient"], coefficient)])
    ins = [vr[n] for n in INPUTS]
    sampled = [vr[n] for n in COUPLING + ("cage_angle",)] + [vr[f"ball_load_{k + 1}"] for k in range(20)]
    everything = _real_vrs(variables)
    t, ok_steps, loaded = 0.0, 0, set()
    for i in range(600):
        u = _inputs(rng)
        if i % 97 == 50:
            u[0], u[1] = 1.0, 0.0                       # |e| far over the limit: refused
        if i % 89 == 40:
            u[rng.randrange(6)] = rng.choice((math.nan, math.inf, -math.inf))
        h = rng.choice((1e-5, 1e-5, 2.5e-6, 1e-4, 0.0)) if i % 71 != 30 else -1e-5
        _same(pair, capsys, lambda f: f.set_real(ins, u))
        status = _same(pair, capsys, lambda f: f.do_step(t, h))
        if status == OK:
            ok_steps += 1
            t += h
        _same(pair, capsys, lambda f: f.get_real(sampled))
        loaded.add(_same(pair, capsys, lambda f: f.get_integer([vr["loaded_balls"]]))[1][0])
        if i % 25 == 0:
            _same(pair, capsys, lambda f: f.get_real(everything))
    _same(pair, capsys, lambda f: f.get_real(everything))
    assert ok_steps > 500 and len(loaded) > 2, "the script must step, in and out of the load zone"
    assert pair.kernel_steps() > 400, "the C step did not run"
    # the life outputs changed: the C step accumulated
    life_vr = [vr["rating_life"], vr["equivalent_load_inner"], vr["equivalent_load_outer"]]
    status, bits = pair.c.get_real(life_vr)
    assert status == OK and len(set(bits)) == 3


def test_refusals_give_the_python_message(pair, model, capsys):
    """NaN input, |e| over the limit, a negative step: the same status and message as the Python step."""
    _, vr, _ = model
    pair.start([1e-5, 0.0, 0.0, 0.0, 100.0, 0.0])
    ins = [vr[n] for n in INPUTS]
    assert _same(pair, capsys, lambda f: f.do_step(0.0, 1e-5)) == OK
    for inputs, h, words in (([math.nan, 0.0, 0.0, 0.0, 100.0, 0.0], 1e-5, "not a finite number"),
                             ([1e-3, 0.0, 0.0, 0.0, 100.0, 0.0], 1e-5, "exceeds eccentricity_limit"),
                             ([1e-5, 0.0, 0.0, 0.0, 100.0, 0.0], -1e-5, "is not >= 0")):
        _same(pair, capsys, lambda f: f.set_real(ins, inputs))
        got = []
        for fmu in pair.both():
            capsys.readouterr()
            got.append((fmu.do_step(1e-5, h), capsys.readouterr().out))
        assert got[0] == got[1]
        assert got[0][0] == DISCARD and words in got[0][1], got[0]
    _same(pair, capsys, lambda f: f.set_real(ins, [2e-5, 1e-6, 0.01, 0.0, 100.0, 5.0]))
    assert _same(pair, capsys, lambda f: f.do_step(2e-5, 1e-5)) == OK
    # refused gets (another type, an unknown value reference): reported by the next step, as by the slave
    for get in (lambda f: f.get_integer([vr["F_x"]]), lambda f: f.get_real([vr["loaded_balls"]]),
                lambda f: f.get_real([99999])):
        _same(pair, capsys, get)
        got = []
        for fmu in pair.both():
            capsys.readouterr()
            got.append((fmu.do_step(3e-5, 1e-5), capsys.readouterr().out))
        assert got[0] == got[1] and got[0][0] == DISCARD, got
    before = pair.kernel_steps()
    assert _same(pair, capsys, lambda f: f.do_step(1e-5, 1e-5)) == OK
    assert pair.kernel_steps() == before + 1, "the C step must take over again after a refused step"


@pytest.mark.parametrize("seed", [11, 12])
def test_c_step_under_the_random_call_script(pair, model, seed):
    """test_loader_fastpath's random sequence (sets, gets, refused parameter sets, NaN and diverged inputs, FMU
    state save/restore/serialisation) with the C step; and fmi2Terminate, fmi2Reset, a second run."""
    md, vr, _ = model
    rng = random.Random(seed)
    start = _inputs(rng)
    ops = _script(rng, vr, 600)
    records = []
    for fmu in pair.both():
        record = []
        os.environ["BEARING_FMU_C_STEP"] = "1"
        try:
            fmu.start(start)
        finally:
            del os.environ["BEARING_FMU_C_STEP"]
        t = _run(fmu, ops, vr, record)
        record.append(("terminate", fmu.dll.fmi2Terminate(fmu.fmu.component)))
        record.append(("step after terminate", fmu.do_step(t, 1e-5)))
        record.append(("get after terminate", fmu.get_real([vr[n] for n in INPUTS + COUPLING])))
        record.append(("reset", fmu.dll.fmi2Reset(fmu.fmu.component)))
        fmu.state = None
        fmu.init(start)
        _run(fmu, ops[:150], vr, record)
        records.append(record)
    assert records[0] == records[1]
    assert pair.kernel_steps() > 100, "the C step did not run"


def test_state_across_c_steps(pair, model, capsys):
    """Get, serialize and set the FMU state between C steps: the restored slave steps on as the Python one."""
    _, vr, variables = model
    rng = random.Random(5)
    pair.start(_inputs(rng))
    ins, everything = [vr[n] for n in INPUTS], _real_vrs(variables)
    for i in range(30):
        u = _inputs(rng)
        _same(pair, capsys, lambda f: f.set_real(ins, u))
        _same(pair, capsys, lambda f: f.do_step(i * 1e-5, 1e-5))
    assert _same(pair, capsys, lambda f: f.save()) == OK            # after C steps: pushed first
    after_save = _same(pair, capsys, lambda f: f.get_real(everything))
    for i in range(30, 60):
        u = _inputs(rng)
        _same(pair, capsys, lambda f: f.set_real(ins, u))
        _same(pair, capsys, lambda f: f.do_step(i * 1e-5, 1e-5))
    assert _same(pair, capsys, lambda f: f.restore()) == OK         # the kernel reloads from the slave
    assert _same(pair, capsys, lambda f: f.get_real(everything)) == after_save
    assert _same(pair, capsys, lambda f: f.serialize_roundtrip())[0] == (OK, OK, OK, OK)
    steps = pair.kernel_steps()
    for i in range(30, 60):
        u = _inputs(rng)
        _same(pair, capsys, lambda f: f.set_real(ins, u))
        _same(pair, capsys, lambda f: f.do_step(i * 1e-5, 1e-5))
        _same(pair, capsys, lambda f: f.get_real(everything))
    assert pair.kernel_steps() == steps + 30
    # a parameter set after initialisation: refused by the slave, reported by the next (Python) step
    assert _same(pair, capsys, lambda f: f.set_real([vr["radial_clearance"]], [1e-5])) == OK
    assert _same(pair, capsys, lambda f: f.do_step(1.0, 1e-5)) == DISCARD
    assert _same(pair, capsys, lambda f: f.do_step(1.0, 1e-5)) == OK
    assert pair.kernel_steps() == steps + 31


def test_directional_derivative_after_c_steps(pair, model):
    """fmi2GetDirectionalDerivative reads the tangent outputs the C step computed."""
    _, vr, _ = model
    rng = random.Random(9)
    pair.start([2e-5, 1e-5, 0.0, 0.0, 100.0, 0.0])
    ins = [vr[n] for n in INPUTS]
    unknown = (ctypes.c_uint * 2)(vr["F_x"], vr["F_y"])
    known = (ctypes.c_uint * 2)(vr["e_x"], vr["v_y"])
    seed = (ctypes.c_double * 2)(1.0, 0.5)
    got = []
    for fmu in pair.both():
        rng = random.Random(9)
        rows = []
        for i in range(20):
            fmu.set_real(ins, [3e-5 * rng.random(), 3e-5 * rng.random(), 0.01, 0.0, 100.0, 0.0])
            assert fmu.do_step(i * 1e-5, 1e-5) == OK
            out = (ctypes.c_double * 2)()
            status = fmu.fmu.fmi2GetDirectionalDerivative(fmu.fmu.component, unknown, 2, known, 2, seed, out) \
                if fmu is pair.c else None
            rows.append((status, fmu.get_real([vr["stiffness_xx"], vr["damping_xy"], vr["stiffness_xy"],
                                              vr["damping_yy"]])[1], tuple(out)))
        got.append(rows)
    for (status, tangents, dd), (_, tangents_py, _) in zip(*got):
        assert status == OK and tangents == tangents_py
        import struct
        kxx, cxy, kxy, cyy = (struct.unpack("<d", b)[0] for b in tangents)
        assert dd == (kxx * 1.0 + cxy * 0.5, kxy * 1.0 + cyy * 0.5)
    assert pair.kernel_steps() == 20


def test_oil_film_keeps_the_python_step(pair, model, capsys):
    """damping_model 2 (oil film) has no C step: the loader's fast path runs the Python step."""
    _, vr, variables = model
    rng = random.Random(3)
    pair.start(_inputs(rng), ints=[(vr["damping_model"], 2)])
    _fifty_steps_alike(pair, capsys, rng, vr, variables)
    assert pair.kernel_steps() == 0


def _fifty_steps_alike(pair, capsys, rng, vr, variables):
    """50 random set/step/get cycles on both sides of ``pair``, every status and value the same."""
    ins, everything = [vr[n] for n in INPUTS], _real_vrs(variables)
    for i in range(50):
        u = _inputs(rng)
        _same(pair, capsys, lambda f: f.set_real(ins, u))
        assert _same(pair, capsys, lambda f: f.do_step(i * 1e-5, 1e-5)) == OK
        _same(pair, capsys, lambda f: f.get_real(everything))


def test_switch_turns_the_c_step_off(ball_bearing_fmu, model, tmp_path, capsys):
    """BEARING_FMU_C_STEP=0 at fmi2Instantiate: no C step, the same values."""
    md, vr, variables = model
    pair = Pair(ball_bearing_fmu, md, tmp_path, kernel="0")
    try:
        rng = random.Random(4)
        pair.start(_inputs(rng))
        _fifty_steps_alike(pair, capsys, rng, vr, variables)
        assert pair.kernel_steps() == 0
    finally:
        pair.free()


def test_master_run_is_the_same_with_and_without_the_c_step(ball_bearing_fmu, tmp_path):
    """``python -m mechanism run --revs 0.2 --no-plots --no-ideal``: the same CSV and summary, byte for byte; the
    loader's C step counts (BEARING_FMU_C_STEP_COUNTS) show that it ran, and did not with the switch off."""
    outs = {}
    for switch in ("1", "0"):
        out = tmp_path / f"run_{switch}"
        counts = tmp_path / f"c_steps_{switch}.txt"   # the loader appends each instance's C steps at its free
        env = dict(os.environ, BEARING_FMU_C_STEP=switch, PYTHONPATH=str(ROOT), BEARING_FMU_C_STEP_COUNTS=str(counts))
        proc = subprocess.run([sys.executable, "-m", "mechanism", "run", "--revs", "0.2", "--no-plots",
                               "--no-ideal", "--quiet", "--fmu", str(ball_bearing_fmu), "--out", str(out)],
                              cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr
        outs[switch] = out
        steps = [int(line) for line in counts.read_text().split()] if counts.exists() else []
        if switch == "1":
            assert steps and max(steps) > 1000, f"the C step did not run: C steps per instance {steps}"
        else:
            assert steps and max(steps) == 0, steps
    names = sorted(p.name for p in outs["1"].iterdir() if not p.name.startswith("."))   # not the lock file
    assert "timeseries.csv" in names
    match, mismatch, errors = filecmp.cmpfiles(outs["1"], outs["0"], names, shallow=False)
    assert not mismatch and not errors, (mismatch, errors)


# --- FMU states saved in C (loader.c, "FMU states in C") -------------------------------------------------------

def _serialized(fmu: Raw, state) -> tuple[int, bytes]:
    size = ctypes.c_size_t()
    s1 = fmu.dll.fmi2SerializedFMUstateSize(fmu.fmu.component, state, ctypes.byref(size))
    buffer = ctypes.create_string_buffer(size.value)
    s2 = fmu.dll.fmi2SerializeFMUstate(fmu.fmu.component, state, buffer, size.value)
    return max(s1, s2), buffer.raw


def _states_saved_in_c(fmu: Raw) -> int:
    function = fmu.dll.bearingLoaderKernelStates
    function.argtypes, function.restype = [ctypes.c_void_p], ctypes.c_longlong
    return function(fmu.fmu.component)


class Side:
    """Two instances "a" and "b" of the FMU through one binary (the loader with the C step, or pythonfmu alone)."""

    def __init__(self, folder: Path, md):
        self.a, self.b = Raw(folder, md, "a"), Raw(folder, md, "b")
        self.states = {}

    def get(self, fmu, key):
        state = self.states.get(key) or ctypes.c_void_p()
        status = fmu.dll.fmi2GetFMUstate(fmu.fmu.component, ctypes.byref(state))
        self.states[key] = state
        return status

    def free_state(self, fmu, key):
        return fmu.dll.fmi2FreeFMUstate(fmu.fmu.component, ctypes.byref(self.states.pop(key)))


@pytest.fixture
def sides(ball_bearing_fmu, model, tmp_path):
    md, _, _ = model
    c = Side(_extract(ball_bearing_fmu, tmp_path / "loader", True), md)
    python = Side(_extract(ball_bearing_fmu, tmp_path / "pythonfmu", False), md)
    yield c, python
    for side in (c, python):
        for fmu in (side.a,) if getattr(side, "freed", False) else (side.a, side.b):
            try:
                fmu.free()
            except Exception:
                pass


def test_fmu_states_saved_in_c_behave_as_pythonfmus(sides, model, capsys):
    """States saved while the C step owns the state: restored on the same instance (stepping between), reused
    by fmi2GetFMUstate, serialized (the same bytes as pythonfmu's), set on another instance (same parameters:
    accepted; other parameters: refused with the slave's message), after fmi2Terminate, after fmi2Reset and
    after the saving instance was freed -- every status, value and message as through pythonfmu alone."""
    _, vr, variables = model
    everything = _real_vrs(variables)
    ins = [vr[n] for n in INPUTS]
    rng = random.Random(21)
    steps = [_inputs(rng) for _ in range(40)]
    records = []
    for side in sides:
        out = []

        def log(*item):
            out.append(item + (capsys.readouterr().out,))

        capsys.readouterr()
        for fmu, n_balls in ((side.a, 8), (side.b, 8)):
            fmu.fmu.instantiate(loggingOn=False)
            fmu.fmu.setupExperiment(startTime=0.0)
            fmu.fmu.enterInitializationMode()
            fmu.set_integer([vr["n_balls"]], [n_balls])
            fmu.set_real(ins, steps[0])
            fmu.fmu.exitInitializationMode()
        a, b = side.a, side.b

        def run(fmu, first, last):
            for i in range(first, last):
                log("set", fmu.set_real(ins, steps[i]))
                log("step", fmu.do_step(i * 1e-5, 1e-5))
                log("get", fmu.get_real([vr["F_x"], vr["cage_angle"], vr["ball_load_1"]]))

        run(a, 0, 10)
        log("save s1", side.get(a, "s1"))
        run(a, 10, 20)
        log("save s2", side.get(a, "s2"))
        log("all", a.get_real(everything))
        run(a, 20, 25)
        log("restore s1", a.dll.fmi2SetFMUstate(a.fmu.component, side.states["s1"]))
        log("all", a.get_real(everything))
        run(a, 10, 20)                                              # the same steps again: the same values
        log("all", a.get_real(everything))
        log("update s1", side.get(a, "s1"))                         # *state != NULL: updated in place
        run(a, 20, 22)
        log("restore s1", a.dll.fmi2SetFMUstate(a.fmu.component, side.states["s1"]))
        log("all", a.get_real(everything))
        run(a, 22, 24)
        log("all", a.get_real(everything))                          # the slave is up to date here
        log("restore s1", a.dll.fmi2SetFMUstate(a.fmu.component, side.states["s1"]))
        log("all", a.get_real(everything))
        log("serialize s2", _serialized(a, side.states["s2"]))
        log("s2 on b", b.dll.fmi2SetFMUstate(b.fmu.component, side.states["s2"]))
        log("all b", b.get_real(everything))
        run(b, 20, 25)
        log("b save", side.get(b, "sb"))
        log("terminate a", a.dll.fmi2Terminate(a.fmu.component))
        log("s1 after terminate", a.dll.fmi2SetFMUstate(a.fmu.component, side.states["s1"]))
        log("all", a.get_real(everything))
        log("step after terminate", a.do_step(1.0, 1e-5))
        log("reset a", a.dll.fmi2Reset(a.fmu.component))
        a.fmu.setupExperiment(startTime=0.0)
        a.fmu.enterInitializationMode()
        a.set_integer([vr["n_balls"]], [9])                         # other parameters after the reset
        a.set_real(ins, steps[0])
        a.fmu.exitInitializationMode()
        run(a, 0, 5)
        log("old s2 on reinitialised a", a.dll.fmi2SetFMUstate(a.fmu.component, side.states["s2"]))
        log("step", a.do_step(2.0, 1e-5))
        log("sb on a", a.dll.fmi2SetFMUstate(a.fmu.component, side.states["sb"]))
        log("all", a.get_real(everything))
        log("save s3", side.get(a, "s3"))
        run(a, 5, 8)
        b.free()                                                    # sb's instance is freed
        side.freed = True
        log("serialize sb after b was freed", _serialized(a, side.states["sb"]))   # used through a
        log("sb on a after b was freed", a.dll.fmi2SetFMUstate(a.fmu.component, side.states["sb"]))
        log("step", a.do_step(3.0, 1e-5))                           # the refusal (other n_balls), reported
        log("s3", a.dll.fmi2SetFMUstate(a.fmu.component, side.states["s3"]))
        log("all", a.get_real(everything))
        for key in list(side.states):
            log("free", key, side.free_state(a, key))
        records.append(out)
    assert _states_saved_in_c(sides[0].a) == 3, "s1, s2 and the update of s1 are saved in C"
    assert len(records[0]) == len(records[1])
    for x, y in zip(*records):
        assert x == y
    names = [r[0] for r in records[0]]
    for refused in ("old s2 on reinitialised a", "sb on a after b was freed"):
        i = names.index(refused)
        set_state, step = records[0][i], records[0][i + 1]
        assert set_state[1] <= 1 and "setFMUstate refused: a state of another instance: n_balls = 8" in set_state[-1]
        assert step[0] == "step" and step[1] == 2 and "refused: setFMUstate refused" in step[-1]
    serialized = records[0][names.index("serialize sb after b was freed")]
    assert serialized[1][0] == OK and b'"n_balls": 8' in serialized[1][1]


# --- review findings ----------------------------------------------------------------------------------------

_FOREIGN_GET_REAL = r"""
#include <stddef.h>
int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *v) {
    for (size_t i = 0; i < n; i++) v[i] = 42.0;
    return 0;
}
"""


_FOREIGN_SCRIPT = r"""
import ctypes, struct, sys
from pathlib import Path
foreign, folder, fmu = sys.argv[1:4]
ctypes.CDLL(foreign, mode=ctypes.RTLD_GLOBAL)       # before the FMU's loader is loaded (it binds at load time)
from fmpy import read_model_description
from test_loader_fastpath import INPUTS, Raw, _extract
md = read_model_description(fmu)
vr = {v.name: v.valueReference for v in md.modelVariables}
f = Raw(_extract(Path(fmu), Path(folder), True), md, "bearing")
f.fmu.instantiate(loggingOn=False)
f.fmu.setupExperiment(startTime=0.0)
f.fmu.enterInitializationMode()
f.set_real([vr[n] for n in INPUTS], [2e-5, 1e-5, 0.0, 0.0, 100.0, 0.0])
f.fmu.exitInitializationMode()
step = f.do_step(0.0, 1e-5)
steps = f.dll.bearingLoaderKernelSteps
steps.argtypes, steps.restype = [ctypes.c_void_p], ctypes.c_longlong
unknown, known = (ctypes.c_uint * 1)(vr["F_x"]), (ctypes.c_uint * 1)(vr["e_x"])
seed, out = (ctypes.c_double * 1)(1.0), (ctypes.c_double * 1)()
status = f.fmu.fmi2GetDirectionalDerivative(f.fmu.component, unknown, 1, known, 1, seed, out)
stiffness = struct.unpack("<d", f.get_real([vr["stiffness_xx"]])[1][0])[0]
print(step, steps(f.fmu.component), status, repr(out[0]), repr(stiffness))
f.free()
"""


def test_directional_derivative_ignores_a_foreign_global_fmi2GetReal(ball_bearing_fmu, tmp_path):
    """Another library exporting fmi2GetReal (another FMU, a host), loaded RTLD_GLOBAL before the FMU (in a
    process of its own): the loader's fmi2GetDirectionalDerivative still reads its own tangent outputs, not the
    foreign function's 42 (it called the exported fmi2GetReal, which the dynamic linker bound to the foreign one)."""
    pytest.importorskip("ziglang", reason="compiling the foreign library needs the 'ziglang' package")
    source = tmp_path / "foreign.c"
    source.write_text(_FOREIGN_GET_REAL, encoding="utf-8")
    library = tmp_path / "libforeign.so"
    proc = subprocess.run([sys.executable, "-m", "ziglang", "cc", "-shared", "-fPIC", "-o", str(library),
                           str(source)], capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.skip(f"no C compiler for the foreign library: {proc.stderr[:300]}")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "tests"), str(ROOT)]))
    env.pop("BEARING_FMU_C_STEP", None)
    proc = subprocess.run([sys.executable, "-c", _FOREIGN_SCRIPT, str(library), str(tmp_path / "fmu"),
                           str(ball_bearing_fmu)], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    step, kernel_steps, status, derivative, stiffness = proc.stdout.split()[-5:]
    assert (step, kernel_steps, status) == ("0", "1", "0")
    assert float(derivative) == float(stiffness) != 42.0


@pytest.mark.parametrize("kernel", ["1", "0"], ids=["c-step", "c-step-off"])
def test_ball_loads_beyond_n_balls_are_0_after_a_failed_initialisation(ball_bearing_fmu, model, tmp_path, kernel,
                                                                       monkeypatch):
    """A failed initialisation with 20 balls (an overflowing force) leaves loads in the per-ball scratch; the next,
    successful one with 8 balls must give 0 for ball_load_9 ... ball_load_20 (their description), with the C step
    on and off, after the initialisation and after a step -- as through pythonfmu alone."""
    md, vr, _ = model
    pair = Pair(ball_bearing_fmu, md, tmp_path, kernel=kernel)
    monkeypatch.setenv("BEARING_FMU_C_STEP", kernel)   # read at fmi2Instantiate
    tail = [vr[f"ball_load_{k}"] for k in range(9, 21)]
    ins = [vr[n] for n in INPUTS]
    import struct
    try:
        got = []
        for fmu in pair.both():
            fmu.fmu.instantiate(loggingOn=False)
            fmu.fmu.setupExperiment(startTime=0.0)
            fmu.fmu.enterInitializationMode()
            fmu.set_integer([vr["n_balls"]], [20])
            fmu.fmu.setBoolean([pair.allow_overlap], [True])
            fmu.set_real(ins, [3e-5, 0.0, 1e306, 0.0, 100.0, 0.0])
            assert fmu.dll.fmi2ExitInitializationMode(fmu.fmu.component) > 2   # refused (overflowing force)
            fmu.set_integer([vr["n_balls"]], [8])
            fmu.set_real(ins, [3e-5, 0.0, 0.0, 0.0, 100.0, 0.0])
            assert fmu.dll.fmi2ExitInitializationMode(fmu.fmu.component) == OK
            after_init = [struct.unpack("<d", b)[0] for b in fmu.get_real(tail)[1]]
            assert fmu.do_step(0.0, 1e-5) == OK
            after_step = [struct.unpack("<d", b)[0] for b in fmu.get_real(tail)[1]]
            got.append((after_init, after_step))
        assert got[0] == got[1] == ([0.0] * 12, [0.0] * 12)
        assert pair.kernel_steps() == (1 if kernel == "1" else 0)
    finally:
        pair.free()


def test_state_with_overflowed_life_sums_is_refused_cleanly(pair, model, capsys):
    """Inputs that overflow the life sums (inf), then a state saved and restored on the same instance: the
    restore is refused with a message (fmi2SetFMUstate's status and the next doStep's fmi2Discard), nothing is
    assigned, no fmi2Fatal or crash -- the same through the C step (state saved in C) and pythonfmu alone."""
    _, vr, _ = model
    ins = [vr[n] for n in INPUTS]
    pair.start([3e-5, 0.0, 0.0, 0.0, 100.0, 0.0])
    assert _same(pair, capsys, lambda f: f.do_step(0.0, 1e-5)) == OK
    _same(pair, capsys, lambda f: f.set_real(ins, [3e-5, 0.0, 1e90, 0.0, 1e45, 0.0]))
    assert _same(pair, capsys, lambda f: f.do_step(1e-5, 1e-5)) == OK
    _same(pair, capsys, lambda f: f.set_real(ins, [3e-5, 0.0, 0.0, 0.0, 100.0, 0.0]))
    assert _same(pair, capsys, lambda f: f.do_step(2e-5, 1e-5)) == OK
    states = {}

    def save(f):
        states[f] = ctypes.c_void_p()
        return f.dll.fmi2GetFMUstate(f.fmu.component, ctypes.byref(states[f]))

    assert _same(pair, capsys, save) == OK
    assert _same(pair, capsys, lambda f: f.do_step(3e-5, 1e-5)) == OK
    before = _same(pair, capsys, lambda f: f.get_real([vr["F_x"], vr["cage_angle"]]))
    capsys.readouterr()
    got = []
    for f in pair.both():
        got.append((f.dll.fmi2SetFMUstate(f.fmu.component, states[f]), capsys.readouterr().out))
    assert got[0] == got[1]
    status, message = got[0]
    assert status <= 1 and "setFMUstate refused" in message and "not a life accumulator state" in message
    assert _same(pair, capsys, lambda f: f.get_real([vr["F_x"], vr["cage_angle"]])) == before   # unchanged
    assert _same(pair, capsys, lambda f: f.do_step(4e-5, 1e-5)) == 2   # the refusal, reported: fmi2Discard
    assert _states_saved_in_c(pair.c) == 1, "the state was saved in C"
    for f in pair.both():
        f.dll.fmi2FreeFMUstate(f.fmu.component, ctypes.byref(states[f]))


def test_states_saved_in_c_used_on_another_instance_leave_the_owner_alone(ball_bearing_fmu, model, tmp_path):
    """Instance B serializes many states that A saved in C, while another thread reads A's life outputs (which
    the loader forwards to A's slave): every read gives A's own values (the reviewer's race.py: the loader used
    to set A's slave to each state to make pythonfmu's state of it)."""
    import struct
    import threading
    import time
    md, vr, _ = model
    folder = _extract(ball_bearing_fmu, tmp_path / "loader", True)
    a, b = Raw(folder, md, "a"), Raw(folder, md, "b")
    ins = [vr[n] for n in INPUTS]
    rng = random.Random(3)
    try:
        for fmu in (a, b):
            fmu.fmu.instantiate(loggingOn=False)
            fmu.fmu.setupExperiment(startTime=0.0)
            fmu.fmu.enterInitializationMode()
            fmu.set_real(ins, [2e-5, 0.0, 0.0, 0.0, 100.0, 0.0])
            fmu.fmu.exitInitializationMode()
        states = []
        for i in range(300):
            a.set_real(ins, _inputs(rng))
            assert a.do_step(i * 1e-5, 1e-5) == OK
            state = ctypes.c_void_p()
            assert a.dll.fmi2GetFMUstate(a.fmu.component, ctypes.byref(state)) == OK
            states.append(state)
        assert _states_saved_in_c(a) == 300
        probe = [vr["equivalent_load_inner"], vr["equivalent_load_outer"], vr["rating_life"]]
        reference = a.get_real(probe)
        stop, wrong, reads = threading.Event(), [], []

        def reader():
            while not stop.is_set():
                got = a.get_real(probe)
                reads.append(1)
                if got != reference:
                    wrong.append([struct.unpack("<d", x)[0] for x in got[1]])

        thread = threading.Thread(target=reader)
        thread.start()
        for _ in range(1000):   # the reader runs before the serializations start
            if reads:
                break
            time.sleep(0.001)
        sizes = []
        try:
            for _ in range(3):
                for state in states:
                    size = ctypes.c_size_t()
                    sizes.append(b.dll.fmi2SerializedFMUstateSize(b.fmu.component, state, ctypes.byref(size)))
        finally:
            stop.set()
            thread.join()
        assert set(sizes) == {OK}
        assert reads and not wrong, f"{len(wrong)} of {len(reads)} reads of A saw another state: {wrong[:2]}"
        for state in states:
            assert a.dll.fmi2FreeFMUstate(a.fmu.component, ctypes.byref(state)) == OK
    finally:
        for fmu in (a, b):
            try:
                fmu.free()
            except Exception:
                pass
