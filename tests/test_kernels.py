"""The compiled paths against their references: force models against ``Scheme.force``, the numba
multibody kernels against the NumPy ``System``, the compiled force law against ``BallBearing``."""
from __future__ import annotations

import random

import pytest

from mechanism.cosim.coupling import SCHEMES, Exchanged, make_scheme


def _exchange(rng: random.Random, t: float) -> Exchanged:
    k = [rng.uniform(-1e7, 1e7) for _ in range(3)]
    c = [rng.uniform(-1e2, 1e2) for _ in range(3)]
    return Exchanged(t, *(rng.uniform(-2e-5, 2e-5) for _ in range(2)), *(rng.uniform(-0.1, 0.1) for _ in range(2)),
                     *(rng.uniform(-500, 500) for _ in range(2)), *k, *c)


@pytest.mark.parametrize("name", sorted(SCHEMES))
@pytest.mark.parametrize("history", [1, 2, 3])
def test_force_model_equals_scheme_force(name, history):
    """Every registered scheme's ``force_model`` gives its ``force`` (the compiled step evaluates the former)."""
    rng = random.Random(hash((name, history)) & 0xFFFF)
    scheme = make_scheme(name)
    h = 1e-5
    for n in range(history):
        scheme.push(_exchange(rng, n * h * (1.0 + 0.3 * n)))   # uneven steps (the adaptive driver)
    t0 = scheme.past[-1].t
    scheme.begin_step(t0, h)
    model = scheme.force_model(t0, h)
    if model is None:
        pytest.skip(f"{name} has no force model (it runs through the Python path)")
    for _ in range(20):
        tau = t0 + rng.uniform(0.0, h)
        args = (tau, rng.uniform(-2e-5, 2e-5), rng.uniform(-2e-5, 2e-5), rng.uniform(-0.1, 0.1),
                rng.uniform(-0.1, 0.1))
        ref, got = scheme.force(*args), model(*args)
        scale = max(1.0, abs(ref[0]), abs(ref[1]))
        assert abs(got[0] - ref[0]) <= 1e-12 * scale and abs(got[1] - ref[1]) <= 1e-12 * scale
