"""The in-process bearing component as one compiled exchange on a state array (numba), for the compiled loop.

``InProcessEndpoint.exchange`` (mechanism.cosim.endpoints) with the compiled law, as data: the component's
whole state is one float64 array ``cs`` (layout below), so the master's get/set FMU state is a copy of it
and an FMU called natively from numba can take the place of ``law_exchange`` with the same contract.

``cs`` = [cage angle, inputs (6), outputs (10: F_x, F_y, k_xx, k_xy, k_yy, c_xx, c_xy, c_yy, loaded_balls,
max_ball_load), ball loads (n_balls), life sums (4: ``LifeAccumulator.STATE_FIELDS``)].

``life_add`` is a second implementation of ``fmu_bearing.life.LifeAccumulator.add`` (ISO/TS 16281,
docs/bearing-life.md), held against it by tests/test_compiled_loop.py.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from fmu_bearing.life import _CUBE_OF_STATIONARY, _TWO_PI, P_STATIONARY
from mechanism.cosim.law_kernel import evaluate
from mechanism.multibody.kernels import LEAF, internal

CS_CAGE, CS_INPUTS, CS_OUT, CS_LOADS = 0, 1, 7, 17


def state_size(n_balls: int) -> int:
    """Length of the component state array ``cs`` for ``n_balls`` balls."""
    return CS_LOADS + n_balls + 4


def pack_state(endpoint) -> np.ndarray:
    """``cs`` of an ``InProcessEndpoint`` with the compiled law (its get_state as one array)."""
    nb = endpoint.n_balls
    cs = np.zeros(state_size(nb))
    cs[CS_CAGE] = endpoint._cage
    cs[CS_INPUTS:CS_INPUTS + 6] = endpoint._inputs
    out = tuple(endpoint._out)
    if len(out) == 10:
        cs[CS_OUT:CS_OUT + 10] = out
    cs[CS_LOADS:CS_LOADS + nb] = endpoint._loads
    cs[CS_LOADS + nb:] = endpoint.life.state()
    return cs


def unpack_state(endpoint, cs: np.ndarray) -> None:
    """Leave ``endpoint`` in the state ``cs`` (the inverse of ``pack_state``; the life sums as they are)."""
    nb = endpoint.n_balls
    endpoint._cage = float(cs[CS_CAGE])
    endpoint._inputs = tuple(cs[CS_INPUTS:CS_INPUTS + 6].tolist())
    endpoint._out = tuple(cs[CS_OUT:CS_OUT + 10].tolist())
    endpoint._law_out[:] = cs[CS_OUT:CS_OUT + 10]
    endpoint._loads[:] = cs[CS_LOADS:CS_LOADS + nb].tolist()
    endpoint._law_loads[:] = cs[CS_LOADS:CS_LOADS + nb]
    life = endpoint.life
    (life.sum_cubed_inner, life.sum_cubed_outer, life.revolutions, life.time) = cs[CS_LOADS + nb:].tolist()


@njit(**LEAF)
def life_add(loads, sums, z, omega_inner, omega_outer, dt):
    """``LifeAccumulator.add`` (load angular velocity 0) on ``sums`` = [sum_cubed_inner, sum_cubed_outer,
    revolutions, time] with the same arithmetic (ISO/TS 16281 cubic and (10/3)-power means, Palmgren-Miner)."""
    s3 = 0.0
    s103 = 0.0
    for r in range(z):
        q = loads[r]
        if q > 0.0:
            s3 += q * q * q
            s103 += q ** P_STATIONARY
    dn = abs(omega_inner - omega_outer) * dt / _TWO_PI    # revolutions of one ring relative to the other
    if s3 > 0.0:
        q_rot3 = s3 / z                                   # (cubic mean)^3
        q_stat3 = (s103 / z) ** _CUBE_OF_STATIONARY       # ((10/3)-power mean)^3
        if abs(omega_inner) >= abs(omega_outer):
            sums[0] += q_rot3 * dn
            sums[1] += q_stat3 * dn
        else:
            sums[0] += q_stat3 * dn
            sums[1] += q_rot3 * dn
    sums[2] += dn
    sums[3] += dt


@internal(LEAF)
def law_exchange(P, eccentricity_limit, cs, h, sent):
    """One exchange of the in-process component (``InProcessEndpoint.exchange``): check the inputs ``sent``,
    advance the cage over h [s] with the ring speeds held (eq. 16), evaluate the law (eq. 18-19) and add the
    step to the life sums. Returns 0, or 1 if the inputs are rejected (non-finite, |e| beyond the limit:
    nothing changed; the caller names the cause with ``BallBearing.check_inputs``)."""
    ex, ey, vx, vy, wi, wo = sent[0], sent[1], sent[2], sent[3], sent[4], sent[5]
    if not (math.isfinite(ex + ey + vx + vy + wi + wo) and math.hypot(ex, ey) <= eccentricity_limit):
        return 1
    for i in range(6):
        cs[CS_INPUTS + i] = sent[i]
    cs[CS_CAGE] = cs[CS_CAGE] + h * (wi * P[11] + wo * P[12])      # BallBearing.advance_cage, eq. (16)
    nb = int(P[0])
    loads = cs[CS_LOADS:CS_LOADS + nb]
    evaluate(P, ex, ey, vx, vy, cs[CS_CAGE], wi, wo, cs[CS_OUT:CS_OUT + 10], loads)
    life_add(loads, cs[CS_LOADS + nb:CS_LOADS + nb + 4], nb, wi, wo, h)
    return 0
