"""mechanism.cosim.fmu_native: the FMU's fmi2 calls made from numba against the same calls through fmpy.

Two instances of dist/BallBearing.fmu get the same sequence of calls, one through fmpy's Python methods
(``FMU2Slave.setReal/doStep/getReal``, the reference), the other natively from an njit loop: the outputs
must be bit-identical, with the loader's C step and with the Python step inside the FMU (BEARING_FMU_C_STEP=0,
read at fmi2Instantiate).
"""
from __future__ import annotations

import ctypes
import gc
import os
import subprocess
import sys
import textwrap
import weakref
from pathlib import Path

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from fmu_bearing.interface import COUPLING_OUTPUT_NAMES, JOINT_INPUT_NAMES
from mechanism.cosim import fmu_native
from mechanism.cosim.endpoints import ExchangeError, FmuEndpoint

ROOT = Path(__file__).resolve().parent.parent
H_STEP = 1e-5
START = (3e-5, 0.0, 0.0, 0.0, -52.0, 125.0)
SHORT = fmu_native.SLOTS - 1


@njit
def _run(H, vr_in, U, T, h, vr_out, OUT):
    """The exchanges of a compiled loop: row k of U in, row k of OUT out; stops at the first refusal."""
    for k in range(U.shape[0]):
        status = fmu_native.exchange(H, vr_in, U[k], T[k], h, vr_out, OUT[k])
        if status < 0 or status > 1:
            return k, status
    return U.shape[0], 0


def _inputs(n: int, seed: int) -> np.ndarray:
    """Random joint inputs: half inside the clearance (no ball loaded), half in the load zone."""
    rng = np.random.default_rng(seed)
    radius = np.where(rng.random(n) < 0.5, rng.uniform(0.0, 1e-5, n), rng.uniform(1e-5, 2e-4, n))
    angle = rng.uniform(0.0, 2 * np.pi, n)
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle), rng.uniform(-0.05, 0.05, (n, 2)),
                            rng.uniform(-200.0, 200.0, (n, 2))])


def _vrs(ep: FmuEndpoint, names) -> np.ndarray:
    return np.array([ep.variables[n].valueReference for n in names], dtype=np.uint32)


@pytest.fixture(params=["1", "0"], ids=["C-step", "Python-step"])
def pair(request, ball_bearing_fmu, monkeypatch, tmp_path):
    """Two initialised endpoints of the FMU (reference, native), the C step switched at instantiation; the
    loader appends each instance's C steps to ``tmp_path / "c_steps.txt"`` when it is freed."""
    monkeypatch.setenv("BEARING_FMU_C_STEP", request.param)
    monkeypatch.setenv("BEARING_FMU_C_STEP_COUNTS", str(tmp_path / "c_steps.txt"))
    eps = [FmuEndpoint(ball_bearing_fmu, instance_name=name) for name in ("reference", "native")]
    for ep in eps:
        ep.initialize(START)
    yield eps
    for ep in eps:
        ep.close()


@pytest.fixture(params=["1", "0"], ids=["C-step", "Python-step"])
def endpoint(request, ball_bearing_fmu, monkeypatch):
    """An initialised endpoint of the FMU, the C step switched at instantiation."""
    monkeypatch.setenv("BEARING_FMU_C_STEP", request.param)
    ep = FmuEndpoint(ball_bearing_fmu)
    ep.initialize(START)
    yield ep
    ep.close()


def test_native_exchanges_are_bit_identical_to_fmpy(pair, tmp_path):
    ref, nat = pair
    H = fmu_native.endpoint_handle(nat)
    vr_in, vr_out = _vrs(nat, JOINT_INPUT_NAMES), _vrs(nat, COUPLING_OUTPUT_NAMES)
    reals = [n for n in nat.sample_names if nat.variables[n].type == "Real"]
    vr_real, vr_int = _vrs(nat, reals), _vrs(nat, ["loaded_balls"])
    U, T = _inputs(1000, seed=11), np.arange(1000) * H_STEP
    expected = np.empty((1000, 8))
    for k in range(1000):    # fmpy's Python calls
        ref.fmu.setReal(list(vr_in), U[k].tolist())
        ref.fmu.doStep(T[k], H_STEP)
        expected[k] = ref.fmu.getReal(list(vr_out))
    got = np.full((1000, 8), np.nan)
    assert _run(H, vr_in, U, T, H_STEP, vr_out, got) == (1000, 0)
    np.testing.assert_array_equal(got, expected)
    assert 0 < np.count_nonzero(expected[:, 0]) < 1000        # in and out of the load zone
    real_out, int_out = np.zeros(len(vr_real)), np.zeros(1, np.int32)
    assert fmu_native.get_reals(H, vr_real, real_out) == 0
    assert fmu_native.get_integers(H, vr_int, int_out) == 0
    np.testing.assert_array_equal(real_out, ref.fmu.getReal(list(vr_real)))
    assert int_out[0] == ref.fmu.getInteger(list(vr_int))[0]
    assert not [m for m in ref.messages + nat.messages if m.startswith(("[ERROR]", "[FATAL]"))]
    for ep in pair:
        ep.close()
    c_steps = [int(x) for x in (tmp_path / "c_steps.txt").read_text().split()]   # the switch took effect
    assert len(c_steps) == 2 and (min(c_steps) >= 1000 if os.environ["BEARING_FMU_C_STEP"] == "1"
                                  else max(c_steps) == 0), c_steps


def test_state_round_trip_repeats_the_step(pair):
    """get_state, steps, set_state, the same steps again: identical outputs; also against fmpy's states."""
    ref, nat = pair
    H = fmu_native.endpoint_handle(nat)
    vr_in, vr_out = _vrs(nat, JOINT_INPUT_NAMES), _vrs(nat, COUPLING_OUTPUT_NAMES)
    U, T = _inputs(60, seed=5), np.arange(60) * H_STEP
    first, again = np.zeros((20, 8)), np.zeros((20, 8))
    assert _run(H, vr_in, U[:40], T[:40], H_STEP, vr_out, np.zeros((40, 8)))[1] == 0
    status, state = fmu_native.get_state(H)
    assert status == 0 and state != 0
    assert _run(H, vr_in, U[40:], T[40:], H_STEP, vr_out, first)[1] == 0
    for _ in range(2):                               # a state can be restored more than once
        assert fmu_native.set_state(H, state) == 0
        assert _run(H, vr_in, U[40:], T[40:], H_STEP, vr_out, again)[1] == 0
        np.testing.assert_array_equal(again, first)
    assert fmu_native.free_state(H, state) == 0
    # the reference instance through fmpy: the same steps and rollback give the same values
    for k in range(40):
        ref.fmu.setReal(list(vr_in), U[k].tolist())
        ref.fmu.doStep(T[k], H_STEP)
    saved = ref.fmu.getFMUstate()
    for k in range(40, 60):
        ref.fmu.setReal(list(vr_in), U[k].tolist())
        ref.fmu.doStep(T[k], H_STEP)
    ref.fmu.setFMUstate(saved)
    ref.fmu.freeFMUstate(saved)
    for k in range(40, 60):
        ref.fmu.setReal(list(vr_in), U[k].tolist())
        ref.fmu.doStep(T[k], H_STEP)
        again[k - 40] = ref.fmu.getReal(list(vr_out))
    np.testing.assert_array_equal(again, first)
    assert np.count_nonzero(first[:, 0]) > 5                  # steps in the load zone among them


def test_native_state_and_fmpy_state_are_interchangeable(endpoint):
    """A state made natively is restored and freed through fmpy: the same pointer, the same binary."""
    H = fmu_native.endpoint_handle(endpoint)
    vr_in, vr_out = _vrs(endpoint, JOINT_INPUT_NAMES), _vrs(endpoint, COUPLING_OUTPUT_NAMES)
    u, out = np.array([5e-5, 1e-5, 0.01, 0.0, -52.0, 125.0]), np.zeros(8)
    status, state = fmu_native.get_state(H)
    assert status == 0
    assert fmu_native.exchange(H, vr_in, u, 0.0, H_STEP, vr_out, out) == 0
    first = out.copy()
    endpoint.set_state(ctypes.c_void_p(state))
    endpoint.free_state(ctypes.c_void_p(state))
    assert fmu_native.exchange(H, vr_in, u, 0.0, H_STEP, vr_out, out) == 0
    np.testing.assert_array_equal(out, first)


def test_refusal_comes_back_as_exchange_error_with_the_fmus_message(endpoint):
    """An eccentricity beyond the limit: the FMU refuses from inside the njit loop, logs through its Python
    logger callback, the status reaches Python, check raises the endpoint's ExchangeError; the host and the
    instance survive (restore the saved state and go on)."""
    H = fmu_native.endpoint_handle(endpoint)
    vr_in, vr_out = _vrs(endpoint, JOINT_INPUT_NAMES), _vrs(endpoint, COUPLING_OUTPUT_NAMES)
    U = np.tile(np.array(START), (10, 1))
    U[6, 0] = 5e-4                                   # beyond 5 % of the ball diameter (0.435 mm)
    T, OUT = np.arange(10) * H_STEP, np.zeros((10, 8))
    status, state = fmu_native.get_state(H)
    k, status = _run(H, vr_in, U, T, H_STEP, vr_out, OUT)
    assert k == 6 and status >= 2
    with pytest.raises(ExchangeError) as err:
        fmu_native.check(status, f"doStep at t = {T[k]:.9g} s", endpoint)
    message = str(err.value)
    assert "BallBearing.fmu" in message and "exceeds eccentricity_limit" in message and "|e| = 0.0005" in message
    assert fmu_native.set_state(H, state) == 0 and fmu_native.free_state(H, state) == 0
    U[6, 0] = START[0]
    assert _run(H, vr_in, U, T, H_STEP, vr_out, OUT) == (10, 0)
    assert np.all(np.isfinite(OUT)) and OUT[-1, 0] != 0.0


def test_bad_arguments_call_nothing(endpoint):
    """Short or strided arrays: BAD_ARGUMENT, no call (the instance steps on); wrong dtypes: a typing error at
    compile time; an invalidated handle: NO_FUNCTION."""
    H = fmu_native.endpoint_handle(endpoint)
    vr_in, vr_out = _vrs(endpoint, JOINT_INPUT_NAMES), _vrs(endpoint, COUPLING_OUTPUT_NAMES)
    u, out = np.array(START), np.zeros(8)
    calls = endpoint.fmu.getReal(list(vr_out))
    assert fmu_native.exchange(H, vr_in, u[:5], 0.0, H_STEP, vr_out, out) == fmu_native.BAD_ARGUMENT
    assert fmu_native.get_reals(H, vr_out, out[:7]) == fmu_native.BAD_ARGUMENT
    assert fmu_native.get_reals(H, vr_out[:4], np.zeros(16)[::2]) == fmu_native.BAD_ARGUMENT
    assert fmu_native.set_state(H, 0) == fmu_native.BAD_ARGUMENT
    np.testing.assert_array_equal(endpoint.fmu.getReal(list(vr_out)), calls)   # nothing was stepped
    with pytest.raises(ExchangeError, match="BAD_ARGUMENT"):
        fmu_native.check(fmu_native.BAD_ARGUMENT, "exchange", endpoint)
    with pytest.raises(TypingError, match="fmi2ValueReference"):
        fmu_native.get_reals(H, vr_out.astype(np.int64), out)
    with pytest.raises(TypingError, match="fmi2Integer"):
        fmu_native.get_integers(H, _vrs(endpoint, ["loaded_balls"]), np.zeros(1))
    assert fmu_native.exchange(H, vr_in, u, 0.0, H_STEP, vr_out, out) == 0
    assert fmu_native.do_step(H[:SHORT], 0.0, H_STEP) == fmu_native.NO_FUNCTION     # not a whole handle
    fmu_native.invalidate(H)
    assert fmu_native.exchange(H, vr_in, u, H_STEP, H_STEP, vr_out, out) == fmu_native.NO_FUNCTION
    assert fmu_native.get_state(H) == (fmu_native.NO_FUNCTION, 0)


def test_native_samples_equal_the_endpoints(endpoint):
    """endpoint_references: native exchange with its coupling references, then the sampled outputs natively
    equal ``FmuEndpoint.sample()`` (its names' order)."""
    H, refs = fmu_native.endpoint_handle(endpoint), fmu_native.endpoint_references(endpoint)
    assert [endpoint.variables[n].valueReference for n in JOINT_INPUT_NAMES] == refs.inputs.tolist()
    assert len(refs.real_samples) + len(refs.int_samples) + len(refs.bool_samples) == len(endpoint.sample_names)
    out = np.zeros(len(refs.coupling))
    assert fmu_native.exchange(H, refs.inputs, np.array([6e-5, -2e-5, 0.01, 0.0, -52.0, 125.0]), 0.0, H_STEP,
                               refs.coupling, out) == 0
    real, integer = np.zeros(len(refs.real_samples)), np.zeros(len(refs.int_samples), np.int32)
    boolean = np.zeros(len(refs.bool_samples), np.int32)
    assert fmu_native.get_reals(H, refs.real_samples, real) == 0
    assert fmu_native.get_integers(H, refs.int_samples, integer) == 0
    assert fmu_native.get_booleans(H, refs.bool_samples, boolean) == 0
    expected = endpoint.sample()
    assert [*real, *map(float, integer), *map(float, boolean)] == expected
    assert integer[0] > 0 and max(real) > 0                      # loaded balls: in the load zone
    row = np.full(len(endpoint.sample_names) + 1, np.nan)
    assert fmu_native.sample_into(H, refs.real_samples, refs.int_samples, refs.bool_samples, row) == 0
    assert row[:-1].tolist() == expected and np.isnan(row[-1])
    assert fmu_native.sample_into(H, refs.real_samples, refs.int_samples, refs.bool_samples,
                                  row[:5]) == fmu_native.BAD_ARGUMENT
    np.testing.assert_array_equal(out, endpoint.fmu.getReal(refs.coupling.tolist()))


def test_sample_into_with_a_boolean_output(journal_clearance_fmu):
    """JournalClearance samples a boolean (in_contact): sample_into gives sample()'s row in and out of contact."""
    ep = FmuEndpoint(journal_clearance_fmu)
    try:
        ep.initialize((0.0,) * 6)
        H, refs = fmu_native.endpoint_handle(ep), fmu_native.endpoint_references(ep)
        assert len(refs.bool_samples) == 1
        row, out, flags = np.zeros(len(ep.sample_names)), np.zeros(len(refs.coupling)), []
        for k, e_x in enumerate((5e-6, 1.2e-5, 1.5e-5, 5e-6)):     # radial clearance 10 um
            u = np.array([e_x, 0.0, 0.01 if k < 2 else -0.01, 0.0, 10.0, 0.0])
            assert fmu_native.exchange(H, refs.inputs, u, k * H_STEP, H_STEP, refs.coupling, out) == 0
            assert fmu_native.sample_into(H, refs.real_samples, refs.int_samples, refs.bool_samples, row) == 0
            assert row.tolist() == ep.sample()
            flags.append(row[ep.sample_names.index("in_contact")])
        assert flags == [0.0, 1.0, 1.0, 0.0]
    finally:
        ep.close()


def test_booleans(ball_bearing_fmu):
    ep = FmuEndpoint(ball_bearing_fmu, {"allow_ball_overlap": True})
    try:
        ep.initialize(START)
        H, out = fmu_native.endpoint_handle(ep), np.zeros(1, np.int32)
        vr = _vrs(ep, ["allow_ball_overlap"])
        assert fmu_native.get_booleans(H, vr, out) == 0
        assert out[0] == 1 and ep.fmu.getBoolean(list(vr)) == [True]
    finally:
        ep.close()


def test_handle_keeps_the_endpoint_alive(ball_bearing_fmu):
    ep = FmuEndpoint(ball_bearing_fmu)
    with pytest.raises(ValueError, match="not initialised"):
        fmu_native.endpoint_handle(ep)
    with pytest.raises(ValueError, match="instantiated"):
        fmu_native.handle(ep.fmu)
    ep.initialize(START)
    H, ref = fmu_native.endpoint_handle(ep), weakref.ref(ep)
    del ep
    gc.collect()
    assert ref() is not None
    out = np.zeros(8)
    assert fmu_native.exchange(H, _vrs(ref(), JOINT_INPUT_NAMES), np.array(START), 0.0, H_STEP,
                               _vrs(ref(), COUPLING_OUTPUT_NAMES), out) == 0 and out[0] > 0
    ref().close()


def test_closing_invalidates_the_handles(ball_bearing_fmu):
    """FmuEndpoint.close (or the slave's freeInstance) zeroes its handles: a late call returns NO_FUNCTION
    instead of reaching the freed instance (which hangs the process)."""
    ep = FmuEndpoint(ball_bearing_fmu)
    ep.initialize(START)
    handles, refs = [fmu_native.endpoint_handle(ep) for _ in range(2)], fmu_native.endpoint_references(ep)
    out = np.zeros(8)
    ep.close()
    for H in handles:
        assert not H.any()
        assert fmu_native.exchange(H, refs.inputs, np.array(START), 0.0, H_STEP, refs.coupling,
                                   out) == fmu_native.NO_FUNCTION
    with pytest.raises(ValueError, match="not initialised"):
        fmu_native.endpoint_handle(ep)


def test_cached_machine_code_serves_a_new_process(ball_bearing_fmu, tmp_path):
    """cache=True: the second process loads the first one's machine code (the addresses are data, not
    constants compiled in) and its exchanges equal fmpy's."""
    script = textwrap.dedent(f"""
        import numpy as np
        from mechanism.cosim import fmu_native
        from mechanism.cosim.endpoints import FmuEndpoint
        ref, nat = (FmuEndpoint({str(ball_bearing_fmu)!r}, instance_name=n) for n in ("a", "b"))
        for ep in (ref, nat):
            ep.initialize({START!r})
        H, out = fmu_native.endpoint_handle(nat), np.zeros(8)
        vr_in, vr_out = np.array(list(nat._vr_in), np.uint32), np.array(list(nat._vr_out), np.uint32)
        for k in range(50):
            u = np.array([6e-5 * np.cos(k), 6e-5 * np.sin(k), 0.01, 0.0, -52.0, 125.0])
            assert fmu_native.exchange(H, vr_in, u, k * 1e-5, 1e-5, vr_out, out) == 0
            assert tuple(out) == ref.exchange(k * 1e-5, 1e-5, u)
        print(fmu_native.exchange.stats.cache_hits.get(fmu_native.exchange.signatures[0], 0))
        ref.close(); nat.close()
    """)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT))
    runs = [subprocess.run([sys.executable, "-c", script], check=False, env=env, cwd=ROOT, capture_output=True, text=True,
                           timeout=300) for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr[-3000:]
    assert [r.stdout.split()[-1] for r in runs] == ["0", "1"]
