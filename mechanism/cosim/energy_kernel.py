"""The bearing side of the energy account over a communication step, from the integrator's stages (numba).

The master's RK4 step records, per substep, its four stage states and its end state (bearing inputs and ring
angles; ``mechanism.multibody.kernels.advance`` or the NumPy path of ``master.CouplingLoop.advance``). Here the
force law's damping power (F - F_el) . v and cage power omega_m (F_el x e)_z (``energy.account_powers``) are
evaluated at those states, per ball, and integrated with the stages' own weights h/6 (1, 2, 2, 1): the
quadrature RK4 applies to a state whose derivative they are (4th order where the powers are smooth).

Contact onsets: with the paper's constant damping a ball entering the load zone switches its damping power
C v_r^2 on at once (eq. 18), a jump that a quadrature over the stages straddles with an O(h) error. For a ball
whose deflection delta_r = e . u_r - P_d/2 changes sign over a substep, the onset's position theta in the
substep is located by linear interpolation of delta_r between the substep's ends, and that ball's share is the
integral over its loaded part of the quadratic through its loaded-formula power (C v_r^2, clamped as the law
does) at the substep's start, middle (mean of the two midpoint stages) and end: O(h^2) in the onset's position
instead of O(h) per onset. The oil-film damping vanishes with the load (no jump) and is integrated as it is.

A second implementation of the law's per-ball arithmetic (``fmu_bearing.ball_bearing.BallBearing.evaluate``,
compiled as ``law_kernel.evaluate`` with the same parameter array ``law_kernel.pack_bearing``); the account's
tests hold it against ``energy.account_powers`` (tests/test_energy.py).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from fmu_bearing.ball_bearing import FILM_SPEED_EXPONENT
from fmu_bearing.parameters import DAMPING_CONSTANT, DAMPING_OIL_FILM
from mechanism.cosim.law_kernel import HEADER, _oil_film
from mechanism.multibody.kernels import KERNEL, LEAF, _u, internal

#: the RK4 weights of the four stages (times h/6)
_WEIGHTS = (1.0, 2.0, 2.0, 1.0)


@internal(LEAF)
def _same_row(stages, a, b):
    """True if the stage rows a and b hold the same state (all 8 fields equal)."""
    for i in range(stages.shape[1]):
        if stages[_u(a), _u(i)] != stages[_u(b), _u(i)]:
            return False
    return True


@internal(LEAF)
def _row_powers(P, stages, row, j, cage_offset, nb, K, half, constant, oil, w_in, w_out, pd, pt, dl):
    """The per-ball damping powers pd[j], the loaded formula's pt[j] and the deflections dl[j] at the stage row
    ``row`` (the law's arithmetic, eq. 18, 29-32); returns the cage power sum over the balls of w (F_el x e)_z."""
    q = _u(row)
    e_x, e_y, v_x, v_y = stages[q, 0], stages[q, 1], stages[q, 2], stages[q, 3]
    wi, wo = stages[q, 4], stages[q, 5]
    cage = cage_offset + w_in * stages[q, 6] + w_out * stages[q, 7]
    c, s = math.cos(cage), math.sin(cage)
    ex, ey = c * e_x + s * e_y, c * e_y - s * e_x
    vx, vy = c * v_x + s * v_y, c * v_y - s * v_x
    speed = (P[5] * abs(wi - wo)) ** FILM_SPEED_EXPONENT if oil else 0.0
    cage_power = 0.0
    for r in range(nb):
        cr, sr = P[_u(HEADER + r)], P[_u(HEADER + nb + r)]
        delta = ex * cr + ey * sr - half
        vr = vx * cr + vy * sr
        dl[_u(j), _u(r)] = delta
        w = K * delta * math.sqrt(delta) if delta > 0.0 else 0.0
        if constant:
            f = w + P[4] * vr
            pt[_u(j), _u(r)] = ((f if f > 0.0 else 0.0) - w) * vr   # noqa: FURB136 (NaN: 0, as the law)
        if delta > 0.0:
            if constant:
                C = P[4]
            elif oil:
                C = _oil_film(P, w, speed)[0]
            else:
                C = 0.0
            f = w + C * vr
            pd[_u(j), _u(r)] = ((f if f > 0.0 else 0.0) - w) * vr   # noqa: FURB136 (NaN: 0, as the law)
            cage_power += w * (cr * ey - sr * ex)
        else:
            pd[_u(j), _u(r)] = 0.0
    return cage_power


@njit(**KERNEL)
def stage_integrals(P, stages, substeps, hs, cage_offset):
    """(D, W_cage) [J] over ``substeps`` substeps of size hs [s] from the rows of ``stages`` (5 per substep:
    e_x, e_y, v_x, v_y, omega_inner, omega_outer, journal angle, housing angle). ``cage_offset``: the kinematic
    cage angle is cage_offset + w_inner * journal angle + w_outer * housing angle (eq. 16 integrated)."""
    nb = int(P[0])
    K, half = P[1], P[2]
    model = int(P[3])
    constant = model == DAMPING_CONSTANT
    oil = model == DAMPING_OIL_FILM
    w_in, w_out = P[11], P[12]
    pd = np.zeros((5, nb))        # the law's damping power per ball
    pt = np.zeros((5, nb))        # the loaded formula's (constant damping), whatever the sign of delta
    dl = np.zeros((5, nb))        # delta
    D = 0.0
    Wc = 0.0
    c6 = hs / 6.0
    end_power = 0.0               # the cage power at the last substep's end
    for sub in range(substeps):
        for j in range(5):
            row = 5 * sub + j
            wi, wo = stages[_u(row), 4], stages[_u(row), 5]
            if j == 0 and sub > 0 and _same_row(stages, row, row - 1):
                # the substep's start is the last one's end (the integrator's rows): its powers as computed there
                for r in range(nb):
                    pd[0, _u(r)], pt[0, _u(r)], dl[0, _u(r)] = pd[4, _u(r)], pt[4, _u(r)], dl[4, _u(r)]
                cage_power = end_power
            else:
                cage_power = _row_powers(P, stages, row, j, cage_offset, nb, K, half, constant, oil, w_in, w_out,
                                         pd, pt, dl)
            if j == 4:
                end_power = cage_power
            else:
                wt = c6 * _WEIGHTS[j]
                for r in range(nb):
                    D += wt * pd[_u(j), _u(r)]
                Wc += wt * (w_in * wi + w_out * wo) * cage_power
        if constant:
            for r in range(nb):
                d0, d1 = dl[0, _u(r)], dl[4, _u(r)]
                if (d0 > 0.0) == (d1 > 0.0):
                    continue
                # an onset or release inside the substep: this ball's share, over its loaded part only
                D -= c6 * (pd[0, _u(r)] + 2.0 * (pd[1, _u(r)] + pd[2, _u(r)]) + pd[3, _u(r)])
                theta = d0 / (d0 - d1)
                a, b = (theta, 1.0) if d1 > 0.0 else (0.0, theta)
                p0, pm, p1 = pt[0, _u(r)], 0.5 * (pt[1, _u(r)] + pt[2, _u(r)]), pt[4, _u(r)]
                b1 = -3.0 * p0 + 4.0 * pm - p1
                b2 = 2.0 * p0 - 4.0 * pm + 2.0 * p1
                D += hs * (p0 * (b - a) + 0.5 * b1 * (b * b - a * a) + b2 * (b * b * b - a * a * a) / 3.0)
    return D, Wc
