"""The monolithic reference's right-hand side compiled with numba: a second implementation of the NumPy
right-hand side of ``mechanism.cosim.monolithic`` (``System.accelerations`` + ``BearingLink`` +
``BallBearing.evaluate`` + ``energy.account_powers``), held against it by tests/test_monolithic_kernel.py
(1e-12 on random states, 1e-9 on a short reference run).

It composes the compiled pieces that are themselves held against their NumPy homes: the multibody kernels
(``mechanism.multibody.kernels``: eq. 9-12, 20-23 with Baumgarte) and the force law (``law_kernel.evaluate``:
eq. 18-19). State y = [q, q', cage angle, D, W_drive, W_cage, W_applied] (the energy states optional), as in
``monolithic.py``.

``Arrays(system, link, bearing)`` packs the model once; ``rhs`` fills dy in place and returns a status
(0 fine, 1 a non-finite bearing input, 2 |e| beyond the bearing's eccentricity limit) so that the caller
raises the bearing's own ``BearingInputError`` (``BallBearing.check_inputs``) instead of the kernel.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from fmu_bearing.ball_bearing import BallBearing
from mechanism.cosim.joint import BearingLink
from mechanism.cosim.law_kernel import evaluate, pack_bearing
from mechanism.multibody import kernels as kn
from mechanism.multibody.kernels import (
    KERNEL,
    _add_link_force,
    _applied,
    _kinematics,
    _link_inputs,
    _rotations,
    _solve,
    powers,
)
from mechanism.multibody.solver import System

#: status of ``rhs``
OK, NON_FINITE, BEYOND_LIMIT = 0, 1, 2


class Arrays:
    """The packed model of a monolithic run (multibody kernels' I, R, L, LR, the law's P) and work arrays."""

    def __init__(self, system: System, link: BearingLink, bearing: BallBearing):
        self.n = system.n
        self.I, self.R = kn.pack(system)
        self.L, self.LR = kn.pack_link(system, link.joint, link.contact_points)
        self.P = pack_bearing(bearing)
        self.W = np.zeros(kn.workspace_size(self.I))
        self.u = np.zeros(6)
        self.out = np.zeros(10)        # the law's output (``law_kernel.evaluate``)
        self.loads = np.zeros(bearing.n_balls)
        self.limit = float(bearing.eccentricity_limit)


@njit(**KERNEL)
def rhs(t, y, I, R, L, LR, P, W, u, out, loads, limit, energy_states, dy):
    """dy/dt at (t, y) into dy; the law's output of the state in ``out`` (F, K, C, loaded balls, max load), its
    ball loads in ``loads``, the bearing inputs in u and lambda (internal order) in W. Returns the status."""
    n = I[1]
    _rotations(y, I, W)
    _applied(I, R, W)                                       # Q^A: gravity
    _link_inputs(y, I, L, LR, W, u)                         # eq. (10)-(12)
    ex, ey, vx, vy, wi, wo = u[0], u[1], u[2], u[3], u[4], u[5]
    if not math.isfinite(ex + ey + vx + vy + wi + wo):      # ``check_joint_inputs``
        return NON_FINITE
    if math.hypot(ex, ey) > limit:
        return BEYOND_LIMIT
    cage = y[2 * n]
    evaluate(P, ex, ey, vx, vy, cage, wi, wo, out, loads)  # eq. (18)-(19)
    fx, fy = out[0], out[1]
    _add_link_force(y, I, L, LR, W, ex, ey, fx, fy)        # eq. (20)-(23)
    for i in range(n):
        dy[i] = y[n + i]
    _kinematics(y, t, I, R, W)
    _solve(y, I, R, W, dy)                                  # eq. (9) with Baumgarte
    cage_velocity = wi * P[11] + wo * P[12]                 # eq. (16)
    dy[2 * n] = cage_velocity
    if energy_states:                                       # ``energy.account_powers``
        el = np.empty(10)
        scratch = np.empty(loads.shape[0])
        evaluate(P, ex, ey, 0.0, 0.0, cage, wi, wo, el, scratch)   # the elastic part (v = 0)
        drive, applied, _ = powers(y, I, R, W)
        dy[2 * n + 1] = (fx - el[0]) * vx + (fy - el[1]) * vy
        dy[2 * n + 2] = drive
        dy[2 * n + 3] = cage_velocity * (el[0] * ey - el[1] * ex)
        dy[2 * n + 4] = applied
    return OK


@njit(**KERNEL)
def deflections(y, I, L, LR, W, u, half, out):
    """delta_r = e . u_r - P_d/2 [m] of every ball at y (``coupling.implicit.ball_deflections``: ball angles
    cage + 2 pi r / N_b, eq. 17-18) into out; the bearing inputs of y in u."""
    n = I[1]
    _rotations(y, I, W)
    _link_inputs(y, I, L, LR, W, u)
    nb = out.shape[0]
    cage = y[2 * n]
    for r in range(nb):
        phi = cage + 2.0 * math.pi * r / nb
        out[r] = u[0] * math.cos(phi) + u[1] * math.sin(phi) - half
