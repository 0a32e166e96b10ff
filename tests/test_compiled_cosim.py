"""The compiled communication step through the FMU (``mode="cosim"``) against the Python loop through fmpy.

The same RunConfig runs with ``MasterSettings.compiled_loop`` False (``run_master`` + ``CouplingLoop``, the FMU
through fmpy: the reference) and True (``compiled_loop.run_steps`` calling the FMU natively, ``fmu_native``).
Same FMU, same inputs in the same order: every column, the meta (counters, component calls, life outputs read
from the FMU, energy figures, failure) and the status must be bit-identical. The FMU's states the rollback
saves are all freed (counted at the FMU's boundary: the handle's fmi2GetFMUstate and fmi2FreeFMUstate slots
pointed at counting ctypes wrappers of the FMU's own functions), and the FMU is closed after the run (its handles
invalidated).
"""
from __future__ import annotations

import ctypes
import functools
import math

import numpy as np
import pytest
from conftest import built_fmu

from mechanism import run as run_module
from mechanism.cosim import compiled_driver, fmu_native
from mechanism.cosim.master import MasterSettings
from mechanism.run import RunConfig, run


def _run(config: RunConfig, compiled: bool, monkeypatch) -> tuple:
    """The run with the compiled loop on or off, and the CompiledLoop objects of its chunks."""
    used = []
    original = compiled_driver.CompiledLoop.run

    def counted(self, first, last, y):
        used.append(self)
        return original(self, first, last, y)

    with monkeypatch.context() as m:
        m.setattr(run_module, "MasterSettings", functools.partial(MasterSettings, compiled_loop=compiled))
        m.setattr(compiled_driver.CompiledLoop, "run", counted)
        return run(config), used


def _compare(config: RunConfig, monkeypatch):
    """Both loops on ``config``: bit-identical samples and meta; returns (reference, compiled, CompiledLoop)."""
    ref, used_ref = _run(config, False, monkeypatch)
    new, used = _run(config, True, monkeypatch)
    assert not used_ref and used                                  # each path ran the loop it names
    assert (new.status, new.message) == (ref.status, ref.message)
    assert new.columns == ref.columns and new.data.shape == ref.data.shape
    for k, column in enumerate(ref.columns):
        np.testing.assert_array_equal(new.data[:, k], ref.data[:, k], err_msg=column)
    assert new.meta == ref.meta
    loop = used[-1]
    assert loop.kind == compiled_driver.cc.FMU
    assert not loop.H.any()                                       # closed by run(): its handle invalidated
    return ref, new, loop


#: fmi2Status f(fmi2Component, fmi2FMUstate*): fmi2GetFMUstate and fmi2FreeFMUstate
_STATE_CALL = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_void_p))


class StateWatch:
    """The FMU states the compiled loop takes and frees, seen at the FMU's boundary: ``endpoint_handle``'s
    fmi2GetFMUstate and fmi2FreeFMUstate slots point at ctypes wrappers calling the FMU's own functions."""

    def __init__(self):
        self.taken, self.freed, self.live, self.errors = 0, 0, set(), []
        self._keep = []

    def handle(self, original, endpoint):
        H = original(endpoint)
        get, free = _STATE_CALL(int(H[fmu_native.GET_STATE])), _STATE_CALL(int(H[fmu_native.FREE_STATE]))

        def watched_get(c, p):
            status = get(c, p)
            if p[0] in self.live:
                self.errors.append(f"state {p[0]:#x} handed out twice")
            self.live.add(p[0])
            self.taken += 1
            return status

        def watched_free(c, p):
            if p[0] not in self.live:
                self.errors.append(f"freeing {p[0]} that is not live")
            self.live.discard(p[0])
            self.freed += 1
            return free(c, p)

        wrappers = (_STATE_CALL(watched_get), _STATE_CALL(watched_free))
        self._keep.append(wrappers)
        H[fmu_native.GET_STATE], H[fmu_native.FREE_STATE] = (ctypes.cast(w, ctypes.c_void_p).value for w in wrappers)
        return H


@pytest.fixture
def states(monkeypatch) -> StateWatch:
    watch = StateWatch()
    monkeypatch.setattr(fmu_native, "endpoint_handle", functools.partial(watch.handle, fmu_native.endpoint_handle))
    return watch


def _cosim(fmu, **kw) -> RunConfig:
    """A co-simulation config; jacobian-implicit unless given: these tests hold the native exchange to fmpy's bit for
    bit (law-model, the default, has its own: tests/test_law_model_coupling.py::test_law_model_through_the_fmu)."""
    return RunConfig(**{"mode": "cosim", "scheme": "jacobian-implicit", "fmu": str(fmu), "progress": False, "step": 1e-5, **kw})


def test_default_run_through_the_fmu(ball_bearing_fmu, states, monkeypatch):
    """1200 rpm, 8 balls, C = 50 N s/m, 0.1 rev, the energy account: samples (the FMU's ball loads, cage angle,
    loaded balls), counters, component calls, life outputs and energy meta bit-identical; every state freed."""
    ref, _, loop = _compare(_cosim(ball_bearing_fmu, rpm=1200, revs=0.1,
                                   settings={"damping_model": 1, "damping_coefficient": 50}), monkeypatch)
    meta = ref.meta
    assert meta["iteration_passes_max"] >= 2 and meta["iteration_predicted"] > 0
    assert meta["component_calls"] == round(meta["iteration_passes_mean"] * 500)
    assert meta["life_outputs"]["equivalent_load_inner"] > 0 and "energy_residual_coupling_J" in meta
    assert ref.has("ball_load_8") and np.nanmax(ref["max_ball_load"]) > 0
    assert loop.states == (500, 500)                              # one FMU state per iterated step, each freed
    assert (states.taken, states.freed, states.live, states.errors) == (500, 500, set(), [])


def test_twenty_balls_every_third_step(ball_bearing_fmu, monkeypatch):
    """300 rpm, 20 overlapping balls (the FMU's capacity), undamped, a sample every 3rd step."""
    ref, _, _ = _compare(_cosim(ball_bearing_fmu, rpm=300, revs=0.05, balls=20, record_every=3,
                                settings={"allow_ball_overlap": True, "damping_model": 0}), monkeypatch)
    assert ref.has("ball_load_20") and len(ref["time"]) == 1 + 1000 // 3 + 1   # and the end, off the stride


def test_explicit_scheme_saves_no_state(ball_bearing_fmu, monkeypatch):
    """jacobian-secant (one pass, secant ring speeds sent): no rollback, no FMU state saved."""
    ref, _, loop = _compare(_cosim(ball_bearing_fmu, rpm=1200, revs=0.02, scheme="jacobian-secant",
                                   record_every=2), monkeypatch)
    assert "iteration_passes_mean" not in ref.meta and loop.states == (0, 0)


@pytest.mark.parametrize("scheme", ["zoh", "extrap1", "extrap2", "zoh-jacobi"])
def test_force_held_schemes(ball_bearing_fmu, scheme, monkeypatch):
    """The schemes of the step-size study that hold or extrapolate the force (Jacobi ordering: the FMU steps
    first, with the last inputs), 300 rpm, C = 50 N s/m, a sample every 2nd step."""
    ref, _, loop = _compare(_cosim(ball_bearing_fmu, rpm=300, revs=0.02, scheme=scheme, record_every=2,
                                   settings={"damping_model": 1, "damping_coefficient": 50}), monkeypatch)
    assert loop.states == (0, 0) and ref.meta["component_calls"] > 0


@pytest.mark.parametrize("settings, step", [({"eccentricity_limit": 1.5e-5}, 1e-5), ({}, 4e-4)])
def test_failure_is_reported_alike(ball_bearing_fmu, settings, step, states, monkeypatch):
    """The FMU refuses |e| beyond its limit: the same step, time, cause (the FMU's logged message), the rows
    so far kept, the saved state of the failing step freed."""
    ref, new, loop = _compare(_cosim(ball_bearing_fmu, rpm=1200, revs=0.1, step=step, settings=settings),
                              monkeypatch)
    failure = ref.meta["failure"]
    assert ref.status == "failed" and new.meta["failure"] == failure
    assert "BallBearing.fmu: doStep at t = " in failure["cause"] and "eccentricity_limit" in failure["cause"]
    assert failure["cause"].startswith("ExchangeError: ")
    assert loop.states[0] == loop.states[1] == failure["step"]
    assert (states.taken, states.freed, states.live, states.errors) == (failure["step"],) * 2 + (set(), [])


def test_python_step_inside_the_fmu(ball_bearing_fmu, states, monkeypatch):
    """BEARING_FMU_C_STEP=0 (pythonfmu's Python step, its own FMU states): still bit-identical, states freed."""
    monkeypatch.setenv("BEARING_FMU_C_STEP", "0")
    _, _, loop = _compare(_cosim(ball_bearing_fmu, rpm=1200, revs=0.03,
                                 settings={"damping_model": 1, "damping_coefficient": 50}), monkeypatch)
    assert loop.states == (150, 150)
    assert (states.taken, states.freed, states.live, states.errors) == (150, 150, set(), [])


def test_journal_clearance_fmu(journal_clearance_fmu, monkeypatch):
    """The journal-bushing FMU (a boolean sample, no contact law, no energy account) through the same loop."""
    ref, _, _ = _compare(_cosim(journal_clearance_fmu, joint="clearance", rpm=1200, revs=0.03), monkeypatch)
    assert ref.has("in_contact")


def test_fmi3_runs_the_python_loop(monkeypatch, tmp_path_factory):
    """An FMI 3.0 FMU falls back to the Python loop (the compiled loop calls FMI 2.0 natively only)."""
    fmu3 = built_fmu("BallBearing3", tmp_path_factory)
    result, used = _run(_cosim(fmu3, rpm=1200, revs=0.005), True, monkeypatch)
    assert result.ok and not used and math.isfinite(result.meta["component_calls"])


@pytest.mark.parametrize("step, revs, balls", [(1e-4, 0.1, 8), (5e-6, 0.02, 20)])
def test_law_model_through_the_fmu(ball_bearing_fmu, step, revs, balls, states, monkeypatch):
    """``law-model`` (the law from the energy account's bearing, the FMU the authority at the step's ends) against
    the Python loop's ``LawModel.force`` with the kernels' mechanism (``law_model_reference``): bit-identical, the
    iterated steps' FMU states all freed."""
    from law_model_reference import kernel_mechanism
    kernel_mechanism(monkeypatch)
    settings = {"damping_model": 1, "damping_coefficient": 50, "n_balls": balls}
    if balls > 8:
        settings["allow_ball_overlap"] = True
    ref, _, loop = _compare(_cosim(ball_bearing_fmu, rpm=1200, revs=revs, step=step, output_interval=step,
                                   scheme="law-model", settings=settings), monkeypatch)
    steps = round(revs * 0.05 / step)
    assert ref.meta["iteration_passes_max"] >= 2 and loop.states == (steps, steps) and loop.law_model
    assert (states.taken, states.freed, states.live, states.errors) == (steps, steps, set(), [])


def test_law_model_failure_through_the_fmu(ball_bearing_fmu, states, monkeypatch):
    """A law-model run the FMU stops (|e| beyond its limit): the same failure and rows, every state freed."""
    from law_model_reference import kernel_mechanism
    kernel_mechanism(monkeypatch)
    ref, new, loop = _compare(_cosim(ball_bearing_fmu, rpm=1200, revs=0.1, step=1e-4, scheme="law-model",
                                     settings={"eccentricity_limit": 1.5e-5}), monkeypatch)
    failure = ref.meta["failure"]
    assert ref.status == "failed" and new.meta["failure"] == failure and "eccentricity_limit" in failure["cause"]
    assert loop.states[0] == loop.states[1] == failure["step"]
    assert (states.taken, states.freed, states.live, states.errors) == (failure["step"],) * 2 + (set(), [])
