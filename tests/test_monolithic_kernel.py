"""The monolithic reference's compiled right-hand side (``mechanism.cosim.monolithic_kernel``) against the NumPy one
(``monolithic.numpy_rhs``: ``System`` + ``BearingLink`` + ``BallBearing`` + ``energy.account_powers``), on random
states and over a short reference run."""
from __future__ import annotations

import numpy as np
import pytest

from fmu_bearing.ball_bearing import BallBearing, BearingInputError
from fmu_bearing.parameters import from_values
from mechanism.cosim import monolithic
from mechanism.cosim.joint import BearingLink
from mechanism.multibody.solver import System
from mechanism.systems.slider_crank import (
    SliderCrankParameters,
    build,
    initial_state,
    slider_crank_observer,
)

SETTINGS = {"constant": {"damping_model": 1, "damping_coefficient": 50.0}, "oil-film": {"damping_model": 2},
            "no damping": {"damping_model": 0}}


def _setup(settings: dict, contact_points: str = "centres", rpm: float = 1200.0):
    params = SliderCrankParameters(rpm=rpm)
    model = build(params, "bearing")
    system = System(model)
    q0, qd0 = initial_state(system, params)
    link = BearingLink(system, model.bearings[0], contact_points)
    return system, link, BallBearing(from_values(settings)), q0, qd0


def _random_states(system, bearing, q0, qd0, count, energy_states, seed=3):
    """States about the start with eccentricities of a few clearances (most balls loaded or not) and any cage angle."""
    rng = np.random.default_rng(seed)
    n = system.n
    scale = 2.0 * bearing.half_clearance
    for _ in range(count):
        y = np.concatenate((q0 + rng.normal(0.0, scale, n), qd0 + rng.normal(0.0, 0.05, n),
                            [rng.uniform(0.0, 2.0 * np.pi)], rng.normal(0.0, 1e-3, 4 if energy_states else 0)))
        yield rng.uniform(0.0, 0.05), y


def _blocks(n: int, energy_states: bool) -> dict[str, slice]:
    out = {"q'": slice(0, n), "q''": slice(n, 2 * n), "cage": slice(2 * n, 2 * n + 1)}
    if energy_states:
        out.update({name: slice(2 * n + 1 + k, 2 * n + 2 + k)
                    for k, name in enumerate(("damping", "drive", "cage work", "applied"))})
    return out


@pytest.mark.parametrize("contact_points", ["centres", "eq15"])
@pytest.mark.parametrize("energy_states", [True, False])
@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_compiled_rhs_equals_the_numpy_rhs_on_random_states(name, energy_states, contact_points):
    """Every block of dy/dt (q', q'', the cage speed, each energy power) within 1e-12 of the NumPy reference,
    relative to the block's magnitude, on 200 random states; the states load 0 to all balls."""
    system, link, bearing, q0, qd0 = _setup(SETTINGS[name], contact_points)
    reference = monolithic.numpy_rhs(system, link, bearing, energy_states)
    compiled = monolithic.compiled_rhs(system, link, bearing, energy_states)
    blocks = _blocks(system.n, energy_states)
    loaded = set()
    for t, y in _random_states(system, bearing, q0, qd0, 200, energy_states):
        a, b = reference(t, y), compiled(t, y)
        assert a.shape == b.shape
        for block, s in blocks.items():
            scale = float(np.max(np.abs(a[s])))
            assert np.max(np.abs(a[s] - b[s])) <= 1e-12 * scale, (block, a[s], b[s])
        ex, ey = link.inputs(y[:system.n], y[system.n:2 * system.n])[:2]
        loaded.add(bearing.evaluate(ex, ey, 0.0, 0.0, float(y[2 * system.n])).loaded_balls)
    assert 0 in loaded and len(loaded) >= 3        # unloaded and loaded states both tried


def test_compiled_rhs_refuses_what_the_bearing_refuses():
    """A state beyond the eccentricity limit, or with a non-finite input: the bearing's own BearingInputError
    (``BallBearing.check_inputs``), the same message as the NumPy path."""
    system, link, bearing, q0, qd0 = _setup(SETTINGS["constant"])
    reference = monolithic.numpy_rhs(system, link, bearing)
    compiled = monolithic.compiled_rhs(system, link, bearing)
    far = np.concatenate((q0, qd0, [0.0], np.zeros(4)))
    journal = link.joint.journal.body
    far[system.slice(journal).start] += 10.0 * bearing.eccentricity_limit
    nan = np.concatenate((q0, qd0, [0.0], np.zeros(4)))
    nan[system.n] = np.nan
    for y in (far, nan):
        with pytest.raises(BearingInputError) as want:
            reference(0.0, y)
        with pytest.raises(BearingInputError) as got:
            compiled(0.0, y)
        assert str(got.value) == str(want.value)


def _reference_run(compiled: bool, rtol: float = 1e-10, revs: float = 0.1):
    system, link, bearing, q0, qd0 = _setup(SETTINGS["constant"])
    t_end = revs * 60.0 / 1200.0
    r = monolithic.run_monolithic(system, link, bearing, q0, qd0, t_end, 1e-5, slider_crank_observer(system),
                                  rtol=rtol, progress=False, compiled=compiled)
    assert r.ok, r.message
    return r


def test_short_reference_run_is_the_same_with_the_compiled_rhs():
    """0.1 revolution at 1200 rpm (the start-up impacts, contact onsets located as events), rtol 1e-10: the peak
    joint force and the max eccentricity of the compiled run within 1e-9 of the NumPy run's, the samples within
    2e-7 of the peak (measured 5e-8: the step sequences part at the integrator's own error, ~1e-8 per step; the
    peaks agreed to 1.5e-10), the same number of contact events."""
    ref, new = _reference_run(False), _reference_run(True)
    assert len(ref["time"]) == len(new["time"])
    for cols in (("F_x", "F_y"), ("e_x", "e_y")):
        a, b = np.hypot(*(ref[c] for c in cols)), np.hypot(*(new[c] for c in cols))
        assert abs(b.max() / a.max() - 1.0) <= 1e-9, cols
        assert np.max(np.abs(a - b)) <= 2e-7 * a.max(), cols
    assert new.meta["contact_events"] == ref.meta["contact_events"] > 0
    residual = abs(new["energy_residual"][-1] - ref["energy_residual"][-1])
    assert residual <= 1e-6 * new["damping_dissipation"][-1]
