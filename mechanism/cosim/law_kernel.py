"""The ball-bearing force law compiled with numba: a SECOND implementation of
``fmu_bearing.ball_bearing.BallBearing.evaluate`` (Xu et al. 2012 eq. 18-19, oil film eq. 29-32) for
the master's in-process path. ``fmu_bearing`` stays the one home of the physics (the FMU must run on
the standard library alone); tests/test_kernels.py holds this kernel against it to 1e-12.

``pack_bearing(bearing)`` turns a validated ``BallBearing`` into one float64 array (its constants);
``evaluate(P, e_x, e_y, v_x, v_y, cage, omega_inner, omega_outer, out, loads)`` writes
``out = [F_x, F_y, k_xx, k_xy, k_yy, c_xx, c_xy, c_yy, loaded_balls, max_ball_load]`` and the
ball loads, with the same arithmetic as the reference.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from fmu_bearing.ball_bearing import (
    FILM_LOAD_EXPONENT,
    FILM_SPEED_EXPONENT,
    BallBearing,
)
from fmu_bearing.parameters import DAMPING_CONSTANT, DAMPING_OIL_FILM
from mechanism.multibody.kernels import KERNEL, LEAF, _u, internal

#: P = [n_balls, K, P_d/2, model, C, entrainment, pre_i, h_i, pre_o, h_o, h_min, w_inner, w_outer, cos, sin, cos^2, cos sin, sin^2 (n_balls each)]
HEADER = 13


def pack_bearing(bearing: BallBearing) -> np.ndarray:
    """The constants of a ``BallBearing`` as the kernel's parameter array."""
    nb = bearing.n_balls
    oil = bearing._oil
    (pi, hi), (po, ho) = oil[0] if oil else ((0.0, 0.0), (0.0, 0.0))
    h_min = oil[1] if oil else 0.0
    head = [nb, bearing.stiffness, bearing.half_clearance, bearing.damping_model, bearing.damping_coefficient,
            bearing._entrainment, pi, hi, po, ho, h_min, bearing._w_inner, bearing._w_outer]
    cols = [[b[k] for b in bearing._balls] for k in range(1, 6)]
    return np.array(head + [v for col in cols for v in col], np.float64)


@internal(LEAF)
def _oil_film(P, load, speed):
    """Ball damping C [N s/m] of the inner and outer films in series (eq. 32) and dC/dW [s/m]."""
    h_min = P[10]
    w43 = load ** (4.0 / 3.0)
    wl = load ** -FILM_LOAD_EXPONENT
    ci = co = dci = dco = 0.0
    for k in range(2):                                     # the inner (k = 0) and the outer film
        pre, h = P[6 + 2 * k], P[7 + 2 * k]
        h0 = h * speed * wl
        if h0 > h_min:
            c = pre * w43 / (h0 * h0 * h0)
            dc = c * (4.0 / 3.0 + 3.0 * FILM_LOAD_EXPONENT) / load
        else:
            c = pre * w43 / (h_min ** 3)
            dc = c * (4.0 / 3.0) / load
        if k == 0:
            ci, dci = c, dc
        else:
            co, dco = c, dc
    total = ci + co
    return ci * co / total, (co * co * dci + ci * ci * dco) / (total * total)


@njit(**LEAF)
def evaluate(P, e_x, e_y, v_x, v_y, cage_angle, omega_inner, omega_outer, out, loads):
    """Per-ball loads (eq. 18) and the resultant (eq. 19) with its tangent stiffness and damping."""
    nb = int(P[0])
    c, s = math.cos(cage_angle), math.sin(cage_angle)
    ex, ey = c * e_x + s * e_y, c * e_y - s * e_x
    vx, vy = c * v_x + s * v_y, c * v_y - s * v_x
    K, half = P[1], P[2]
    model = int(P[3])
    C = P[4] if model == DAMPING_CONSTANT else 0.0
    oil = model == DAMPING_OIL_FILM
    speed = (P[5] * abs(omega_inner - omega_outer)) ** FILM_SPEED_EXPONENT if oil else 0.0
    fx = fy = kxx = kxy = kyy = cc = cs_ = ss = 0.0
    n_loaded, f_max = 0, 0.0
    for r in range(nb):
        cr, sr = P[_u(HEADER + r)], P[_u(HEADER + nb + r)]
        delta = ex * cr + ey * sr - half
        if delta <= 0.0:
            loads[_u(r)] = 0.0
            continue
        root = math.sqrt(delta)
        w = K * delta * root                               # Hertz, eq. (18)
        vr = vx * cr + vy * sr
        if oil:                                            # eq. (29)-(32)
            C, dC_dW = _oil_film(P, w, speed)
            kt = 1.5 * K * root * (1.0 + dC_dW * vr)
        else:
            kt = 1.5 * K * root
        f = w + C * vr
        if f <= 0.0:                                       # a contact cannot pull
            loads[_u(r)] = 0.0
            continue
        loads[_u(r)] = f
        crr, crs, srr = P[_u(HEADER + 2 * nb + r)], P[_u(HEADER + 3 * nb + r)], P[_u(HEADER + 4 * nb + r)]
        fx += f * cr
        fy += f * sr
        kxx += kt * crr
        kxy += kt * crs
        kyy += kt * srr
        cc += C * crr
        cs_ += C * crs
        ss += C * srr
        n_loaded += 1
        if f > f_max:                                      # noqa: PLR1730 (a NaN is skipped, as the law)
            f_max = f
    c2, s2, cs2 = c * c, s * s, c * s                      # F = R f, K = R k R^T (eq. 19)
    out[0] = c * fx - s * fy
    out[1] = s * fx + c * fy
    out[2] = c2 * kxx - 2.0 * cs2 * kxy + s2 * kyy
    out[3] = cs2 * (kxx - kyy) + (c2 - s2) * kxy
    out[4] = s2 * kxx + 2.0 * cs2 * kxy + c2 * kyy
    out[5] = c2 * cc - 2.0 * cs2 * cs_ + s2 * ss
    out[6] = cs2 * (cc - ss) + (c2 - s2) * cs_
    out[7] = s2 * cc + 2.0 * cs2 * cs_ + c2 * ss
    out[8] = n_loaded
    out[9] = f_max


@njit(**KERNEL, inline="always")
def sym_eig_max(a, b, c):
    """Largest eigenvalue of [[a, b], [b, c]] (``coupling.base.sym_eig_max``, same arithmetic): the stiffest
    direction of a tangent K or C, for the substep counts of the compiled loop and of law-model's step."""
    return 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)


@njit(**KERNEL, inline="always")
def edge_tolerance(half, e_x, e_y, angle):
    """The margin [m] beyond which a ball's deflection delta_r = e . u_r - P_d/2 (eq. 18) computed from e in the cage's
    frame and the table of the balls' places (cos, sin of 2 pi r / nb; one cos, sin per cage ``angle`` [rad]) has the
    sign of the exact one (its own cos, sin of the ball angle, eq. 17): that shortcut is within |e| 1e-15 (8 + |angle|)
    of the exact deflection (the rounding of the angles and of a few products), about 1000 times inside this. A ball
    farther than this from the load zone's edge is settled by the shortcut; the others by the exact arithmetic."""
    return 1e-12 * (half + (abs(e_x) + abs(e_y)) * (8.0 + abs(angle)))


@njit(**LEAF)
def elastic_energy(P, e_x, e_y, cage_angle):
    """Strain energy of the loaded contacts, sum of (2/5) K delta_r^2.5 [J]: ``BallBearing.elastic_energy``
    (the integral of eq. 18's Hertz term) with the same arithmetic (ball angles of eq. 17)."""
    nb = int(P[0])
    K, half = P[1], P[2]
    # a ball clearly unloaded adds nothing: settled from e in the cage's frame and the table of the balls' places
    # (cos, sin of 2 pi r / nb), within |e| 1e-15 (8 + |angle|) of the exact deflection, far inside tol; the
    # others with the exact arithmetic, as before
    c, s = math.cos(cage_angle), math.sin(cage_angle)
    ex, ey = c * e_x + s * e_y, c * e_y - s * e_x
    tol = edge_tolerance(half, e_x, e_y, cage_angle)
    total = 0.0
    for r in range(nb):
        if ex * P[_u(HEADER + r)] + ey * P[_u(HEADER + nb + r)] - half < -tol:
            continue
        phi = cage_angle + 2.0 * math.pi * r / nb
        delta = e_x * math.cos(phi) + e_y * math.sin(phi) - half
        if delta > 0:
            total += 0.4 * K * delta ** 2.5
    return total
