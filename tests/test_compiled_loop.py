"""The compiled communication step (mechanism.cosim.compiled_loop) against the Python loop, its reference.

The same RunConfig runs with ``MasterSettings.compiled_loop`` False (``run_master`` + ``CouplingLoop``) and
True; every column of the sample table, the meta (counters, life outputs, energy figures, failure) and the
status must agree. Its pieces are held against their homes: ``life_add`` against
``fmu_bearing.life.LifeAccumulator.add``, ``onset_jumps`` against ``coupling.implicit.onset_jumps``.
"""
from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from fmu_bearing import life
from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import BearingParameters
from mechanism import run as run_module
from mechanism.cosim import compiled_driver, compiled_loop, component_kernel
from mechanism.cosim.coupling import Exchanged
from mechanism.cosim.coupling.implicit import onset_jumps
from mechanism.cosim.endpoints import InProcessEndpoint
from mechanism.cosim.joint import BearingLink
from mechanism.cosim.law_kernel import pack_bearing
from mechanism.cosim.master import MasterSettings, RunFailure, run_master
from mechanism.multibody.solver import System
from mechanism.run import RunConfig, run
from mechanism.systems.slider_crank import (
    SliderCrankParameters,
    build,
    initial_state,
    slider_crank_observer,
)

RTOL = 1e-9
#: the scheme of the tests that hold the compiled loop's mechanics (chunks, energy account, failures, the end
#: sample) to the Python loop's pointwise; law-model (the default) has its own tests below
IMPLICIT = "jacobian-implicit"


def _run(config: RunConfig, compiled: bool, monkeypatch) -> tuple:
    """The run with the compiled loop on or off, and how many chunks the compiled loop ran."""
    chunks = []
    original = compiled_driver.CompiledLoop.run

    def counted(self, first, last, y):
        chunks.append((first, last))
        return original(self, first, last, y)

    with monkeypatch.context() as m:
        m.setattr(run_module, "MasterSettings", functools.partial(MasterSettings, compiled_loop=compiled))
        m.setattr(compiled_driver.CompiledLoop, "run", counted)
        return run(config), len(chunks)


def _close(a, b) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, float) and isinstance(b, float):
        return a == b or math.isclose(a, b, rel_tol=RTOL, abs_tol=0.0)
    return a == b


def _compare(config: RunConfig, monkeypatch):
    ref, n_ref = _run(config, False, monkeypatch)
    new, n_new = _run(config, True, monkeypatch)
    assert n_ref == 0 and n_new > 0                       # each path ran the loop it names
    assert (new.status, new.message) == (ref.status, ref.message)
    assert new.columns == ref.columns
    assert new.data.shape == ref.data.shape
    for k, column in enumerate(ref.columns):
        np.testing.assert_allclose(new.data[:, k], ref.data[:, k], rtol=RTOL, atol=0.0, equal_nan=True,
                                   err_msg=column)
    peak = [float(np.max(np.hypot(r["F_x"], r["F_y"]))) for r in (ref, new)]
    assert math.isclose(peak[1], peak[0], rel_tol=RTOL)
    assert new.meta.keys() == ref.meta.keys()
    for key in ref.meta:
        assert _close(new.meta[key], ref.meta[key]), key
    return ref, new


def test_default_run_with_the_energy_account(monkeypatch):
    """1200 rpm, 8 balls, C = 50 N s/m, 0.1 rev: samples, counters, life outputs and energy meta agree."""
    ref, _ = _compare(RunConfig(scheme=IMPLICIT, mode="inprocess", rpm=1200, revs=0.1, step=1e-5, progress=False,
                                settings={"damping_model": 1, "damping_coefficient": 50}), monkeypatch)
    assert ref.has("energy_residual") and "energy_residual_coupling_J" in ref.meta   # mechanism.run's account
    assert ref.meta["iteration_passes_max"] >= 2 and ref.meta["iteration_predicted"] > 0
    assert ref.meta["life_outputs"]["equivalent_load_inner"] > 0


def test_twenty_balls_undamped_every_third_step(monkeypatch):
    """300 rpm, 20 (overlapping) balls, no damping, a sample every 3rd step."""
    ref, _ = _compare(RunConfig(scheme=IMPLICIT, mode="inprocess", rpm=300, revs=0.05, step=1e-5, balls=20, record_every=3, progress=False,
                                settings={"allow_ball_overlap": True, "damping_model": 0}), monkeypatch)
    assert ref.has("ball_load_20") and len(ref["time"]) == 1 + 1000 // 3 + 1   # and the end, off the stride


def test_oil_film_and_substeps(monkeypatch):
    """The oil-film damping (eq. 29-32: no onset jumps) and several RK4 substeps per step."""
    ref, _ = _compare(RunConfig(scheme=IMPLICIT, mode="inprocess", rpm=1200, revs=0.03, progress=False,
                                settings={"damping_model": 2}), monkeypatch)
    assert ref.meta["substeps_max"] > 1


def test_large_step_not_converged(monkeypatch):
    """A step of 1e-4 s: substeps, max_iterations reached (not converged) on many steps."""
    ref, _ = _compare(RunConfig(scheme=IMPLICIT, mode="inprocess", rpm=1200, revs=0.05, step=1e-4, progress=False), monkeypatch)
    assert ref.meta["iteration_not_converged"] > 0


@pytest.mark.parametrize("scheme", ["jacobian", "jacobian-drift", "jacobian-secant", "zoh", "extrap1", "extrap2",
                                    "zoh-jacobi"])
def test_explicit_schemes(scheme, monkeypatch):
    """The one-pass schemes: interface-Jacobian, and the force held or extrapolated (Gauss-Seidel and Jacobi)."""
    ref, _ = _compare(RunConfig(mode="inprocess", rpm=1200, revs=0.02, scheme=scheme, record_every=2,
                                progress=False), monkeypatch)
    assert "iteration_passes_mean" not in ref.meta


@pytest.mark.parametrize("settings, step", [({"eccentricity_limit": 1.5e-5}, 1e-5), ({}, 4e-4)])
def test_failure_is_reported_alike(settings, step, monkeypatch):
    """A run stopped by the component (|e| beyond the limit): the same step, time, cause and kept rows."""
    ref, new = _compare(RunConfig(scheme=IMPLICIT, mode="inprocess", rpm=1200, revs=0.1, step=step, settings=settings,
                                  progress=False), monkeypatch)
    assert ref.status == "failed" and "eccentricity" in ref.meta["failure"]["cause"]
    assert new.meta["failure"] == ref.meta["failure"]


def test_other_paths_run_the_python_loop(monkeypatch):
    """The law not compiled, or the kernels off, fall back to the Python loop."""
    monkeypatch.setattr(run_module, "InProcessEndpoint", functools.partial(InProcessEndpoint, compiled=False))
    result, chunks = _run(RunConfig(scheme=IMPLICIT, mode="inprocess", rpm=1200, revs=0.01, progress=False), True, monkeypatch)
    assert result.ok and chunks == 0
    monkeypatch.setattr(compiled_driver.CompiledLoop, "__init__", None)    # would fail if used
    settings = functools.partial(MasterSettings, kernels=False)
    with monkeypatch.context() as m:
        m.setattr(run_module, "MasterSettings", settings)
        assert run(RunConfig(scheme=IMPLICIT, mode="inprocess", rpm=1200, revs=0.005, progress=False)).ok


def test_life_add_matches_the_accumulator():
    """``component_kernel.life_add`` against ``LifeAccumulator.add`` (ISO/TS 16281), both ring branches."""
    rng = np.random.default_rng(3)
    params = BearingParameters()
    acc = life.LifeAccumulator(life.LoadRatings.of_bearing(params))
    z = acc.n_balls
    sums = np.zeros(4)
    for k in range(200):
        loads = np.where(rng.random(z) < 0.5, 0.0, rng.random(z) * 500.0)
        wi, wo = rng.normal(0, 100.0, 2)
        if k % 7 == 0:
            loads[:] = 0.0
        acc.add(loads.tolist(), wi, wo, 1e-5)
        component_kernel.life_add(loads, sums, z, wi, wo, 1e-5)
        np.testing.assert_allclose(sums, acc.state(), rtol=1e-14, atol=0.0)


def test_onset_jumps_match_the_scheme():
    """``compiled_loop.onset_jumps`` against ``coupling.implicit.onset_jumps`` over random step ends."""
    bearing = BallBearing(BearingParameters(damping_model=1, damping_coefficient=50.0))
    P = pack_bearing(bearing)
    rng = np.random.default_rng(5)
    half = bearing.half_clearance
    jumps = np.zeros((bearing.n_balls, 3))
    found = 0
    for _ in range(300):
        e = rng.normal(0.0, 1.5 * half, 4)
        v = rng.normal(0.0, 0.05, 4)
        a = Exchanged(0.0, e[0], e[1], v[0], v[1], 0.0, 0.0)
        b = Exchanged(1e-5, e[2], e[3], v[2], v[3], 0.0, 0.0)
        cage_a, cage_b = rng.uniform(0, 6.3), rng.uniform(0, 6.3)
        expected = onset_jumps(bearing, a, cage_a, b, cage_b)
        xa = np.array([a.t, a.e_x, a.e_y, a.v_x, a.v_y] + [0.0] * 8)
        xb = np.array([b.t, b.e_x, b.e_y, b.v_x, b.v_y] + [0.0] * 8)
        count = compiled_loop.onset_jumps(P, xa, cage_a, xb, cage_b, jumps)
        assert count == len(expected)
        np.testing.assert_allclose(jumps[:count], np.array(expected).reshape(-1, 3), rtol=1e-13, atol=0.0)
        found += count
    assert found > 50


def test_onset_jumps_match_the_scheme_at_the_load_zones_edge():
    """``compiled_loop.onset_jumps`` (which settles the balls far from the load zone's edge from one cos and sin per
    end) against ``coupling.implicit.onset_jumps`` bit for bit where it matters: e at the clearance at both ends
    (balls entering and leaving the load zone), cage angles up to 1e4 rad."""
    bearing = BallBearing(BearingParameters(damping_model=1, damping_coefficient=50.0))
    P = pack_bearing(bearing)
    rng = np.random.default_rng(6)
    half = bearing.half_clearance
    jumps = np.zeros((bearing.n_balls, 3))
    found = 0
    for trial in range(2000):
        phase, radius = rng.uniform(0, 2 * math.pi), half * (1 + rng.normal(0, 0.05))
        ends = [(radius * (1 + rng.normal(0, 0.02)), phase + rng.normal(0, 0.1)) for _ in range(2)]
        v = rng.normal(0.0, 0.05, 4)
        a = Exchanged(0.0, ends[0][0] * math.cos(ends[0][1]), ends[0][0] * math.sin(ends[0][1]), v[0], v[1], 0.0, 0.0)
        b = Exchanged(1e-5, ends[1][0] * math.cos(ends[1][1]), ends[1][0] * math.sin(ends[1][1]), v[2], v[3], 0.0,
                      0.0)
        cage_a = rng.uniform(-7, 7) if trial % 2 else rng.uniform(-1e4, 1e4)
        cage_b = cage_a + rng.normal(0, 0.01)
        expected = onset_jumps(bearing, a, cage_a, b, cage_b)
        xa = np.array([a.t, a.e_x, a.e_y, a.v_x, a.v_y] + [0.0] * 8)
        xb = np.array([b.t, b.e_x, b.e_y, b.v_x, b.v_y] + [0.0] * 8)
        count = compiled_loop.onset_jumps(P, xa, cage_a, xb, cage_b, jumps)
        assert count == len(expected), trial
        assert [tuple(row) for row in jumps[:count]] == [tuple(j) for j in expected], trial
        found += count
    assert found > 100


@pytest.mark.parametrize("with_law, options", [(False, {}), (True, {}),
                                               (True, {"iterate_where_needed": False, "max_iterations": 3})])
def test_without_energy_account(with_law, options):
    """``run_master`` without an energy account, with and without the contact law locating onsets, and
    iterating until two passes agree (no prediction) with at most 3 passes."""
    params = SliderCrankParameters(rpm=1200)
    model = build(params, "bearing")
    system = System(model)
    q0, qd0 = initial_state(system, params)
    results = []
    for compiled in (False, True):
        endpoint = InProcessEndpoint({"damping_model": 1, "damping_coefficient": 50.0})
        settings = MasterSettings(scheme=IMPLICIT, t_end=0.02 * 60 / 1200, step=1e-5, progress=False, compiled_loop=compiled,
                                  **options)
        results.append(run_master(system, q0, qd0, settings, slider_crank_observer(system),
                                  link=BearingLink(system, model.bearings[0]), endpoint=endpoint,
                                  contact_law=endpoint.bearing if with_law else None))
    ref, new = results
    assert ref.ok and new.ok and not ref.has("energy_residual")
    np.testing.assert_allclose(new.data, ref.data, rtol=RTOL, atol=0.0)
    assert all(_close(new.meta[k], ref.meta[k]) for k in ref.meta) and new.meta.keys() == ref.meta.keys()


def test_the_poll_between_chunks_stops_the_run_alike():
    """The observer's poll (mechanism.run's signal check) runs every 500 steps; raising there stops both loops
    at the same step with the same rows."""
    params = SliderCrankParameters(rpm=1200)
    model = build(params, "bearing")
    system = System(model)
    q0, qd0 = initial_state(system, params)
    inner = slider_crank_observer(system)

    def observe(q, qd, qdd, lam, t):
        return inner(q, qd, qdd, lam, t)

    def poll(t):
        if t > 0.0045:
            raise RunFailure(-1, t, "interrupted by SIGINT")

    observe.probes, observe.poll = inner.probes, poll
    results = []
    for compiled in (False, True):
        endpoint = InProcessEndpoint({"damping_model": 1, "damping_coefficient": 50.0})
        settings = MasterSettings(scheme=IMPLICIT, t_end=0.2 * 60 / 1200, step=1e-5, progress=False, compiled_loop=compiled)
        results.append(run_master(system, q0, qd0, settings, observe, link=BearingLink(system, model.bearings[0]),
                                  endpoint=endpoint, contact_law=endpoint.bearing))
    ref, new = results
    assert ref.status == new.status == "failed" and new.message == ref.message
    assert new.meta["failure"] == ref.meta["failure"] and len(ref.data) == 501
    np.testing.assert_array_equal(new.data, ref.data)


def test_the_runs_end_is_recorded_off_the_output_stride(monkeypatch):
    """903 rpm, 0.1 rev at 5e-6 s, samples every 1e-5 s: 1329 steps, an odd count. Both loops record
    the end state (t_end_s) as the last sample, besides every 2nd step, and agree."""
    ref, _ = _compare(RunConfig(scheme=IMPLICIT, mode="inprocess", rpm=903, revs=0.1, step=5e-6, progress=False,
                                settings={"damping_model": 1, "damping_coefficient": 50}), monkeypatch)
    n = round(0.1 * 60 / 903 / 5e-6)
    assert n % 2 == 1 and ref.meta["t_end_s"] == n * 5e-6
    t = ref["time"]
    assert t[-1] == ref.meta["t_end_s"] and len(t) == 1 + n // 2 + 1
    assert np.allclose(np.diff(t[:-1]), 1e-5) and math.isclose(t[-1] - t[-2], 5e-6)


def test_substeps_match_the_masters_for_huge_tangents():
    """``compiled_loop.substeps`` against ``master.substeps``, also where h * rate / limit is beyond int64 (numba's
    ceil would give INT64_MIN there: the cap, as Python gives)."""
    from mechanism.cosim import compiled_loop as cl
    from mechanism.cosim.coupling import Exchanged
    from mechanism.cosim.master import substeps
    rng = np.random.default_rng(3)
    for k in [0.0, 1e6, 1e8, 3e9, 1e45, *rng.uniform(0, 1e10, 20)]:
        x = Exchanged(0.0, 0, 0, 0, 0, 0, 0, k, 0.1 * k, 0.5 * k, 50.0, 5.0, 20.0)
        arr = np.array([x.t, x.e_x, x.e_y, x.v_x, x.v_y, x.F_x, x.F_y, x.k_xx, x.k_xy, x.k_yy, x.c_xx, x.c_xy, x.c_yy])
        for h in (1e-6, 1e-5, 1e-4, 1e20):
            assert cl.substeps(h, arr, 3.0, 1.0, 64) == substeps(h, x, 3.0, 1.0, 64), (k, h)


@pytest.mark.parametrize("step, revs, balls", [(1e-4, 0.2, 8), (5e-6, 0.02, 20), (1e-5, 0.25, 8)])
def test_law_model_bit_for_bit(step, revs, balls, monkeypatch):
    """``law-model`` (``law_model_kernel``) against the Python loop's ``LawModel.force`` with the kernels' mechanism
    (``law_model_reference.kernel_mechanism``): bit-identical samples and meta, at the coarse step (contact onsets,
    substeps from the law's tangent, onset corrections), at a fine step with 20 balls, and at the default step over
    1250 steps (the compiled loop's chunks of 500: its state carried across two chunk boundaries)."""
    from law_model_reference import kernel_mechanism
    kernel_mechanism(monkeypatch)
    settings = {"damping_model": 1, "damping_coefficient": 50.0, "n_balls": balls}
    if balls > 8:
        settings["allow_ball_overlap"] = True
    ref, new = _compare(RunConfig(mode="inprocess", rpm=1200, revs=revs, step=step, output_interval=step,
                                  scheme="law-model", settings=settings, progress=False), monkeypatch)
    for k, column in enumerate(ref.columns):
        np.testing.assert_array_equal(new.data[:, k], ref.data[:, k], err_msg=column)
    assert new.meta == ref.meta
    assert ref.meta["scheme"] == "law-model" and ref.meta["iteration_passes_max"] >= 2
    if step == 1e-4:
        assert ref.meta["substeps_max"] > 1 and ref.has("ball_load_8")


def test_law_model_against_the_numpy_reference(monkeypatch):
    """``law-model`` compiled against the unpatched Python loop (its NumPy mechanism: other rounding), 0.1 rev at
    1e-4 s: every column within 1e-9 of its largest magnitude (the constraint violation, a rounding-level figure,
    within 1e-14 m; the energy residual, a difference of the energies, within 1e-9 of the kinetic energy), the same
    passes and substeps."""
    config = RunConfig(mode="inprocess", rpm=1200, revs=0.1, step=1e-4, output_interval=1e-4, scheme="law-model",
                       settings={"damping_model": 1, "damping_coefficient": 50.0}, progress=False)
    ref, n_ref = _run(config, False, monkeypatch)
    new, n_new = _run(config, True, monkeypatch)
    assert n_ref == 0 and n_new > 0 and ref.ok and new.ok and new.columns == ref.columns
    for k, column in enumerate(ref.columns):
        a, b = ref.data[:, k], new.data[:, k]
        floor = {"constraint_violation": 1e-14,
                 "energy_residual": 1e-9 * np.max(np.abs(ref["kinetic_energy"]))}.get(column, 0.0)
        assert np.max(np.abs(a - b)) <= 1e-9 * np.max(np.abs(a)) + floor, column
    for key in ("substeps_max", "substeps_total", "iteration_passes_mean", "iteration_passes_max",
                "iteration_not_converged", "component_calls"):
        assert new.meta[key] == ref.meta[key], key


def test_law_model_failure_is_reported_alike(monkeypatch):
    """A law-model run stopped by the component (|e| beyond the limit): same step, time, cause and rows."""
    from law_model_reference import kernel_mechanism
    kernel_mechanism(monkeypatch)
    ref, new = _compare(RunConfig(mode="inprocess", rpm=1200, revs=0.1, step=1e-4, scheme="law-model",
                                  settings={"eccentricity_limit": 1.5e-5}, progress=False), monkeypatch)
    assert ref.status == "failed" and "eccentricity" in ref.meta["failure"]["cause"]
    assert new.meta["failure"] == ref.meta["failure"]
    np.testing.assert_array_equal(new.data, ref.data)
