"""The ``law-model`` coupling's step compiled (numba), for the compiled loop (``compiled_loop.run_steps``).

A second implementation of ``mechanism.cosim.coupling.law_model.LawModel`` (its Python path, ``force`` called
by the master's RK4, is the reference; tests/test_compiled_loop.py and tests/test_compiled_cosim.py hold the
compiled loop's law-model runs against it) with the same arithmetic and order:

    F(tau, e, v) = F_law(e, v; phi_n + omega_m s) + g_k + c_n + (c* - c_n) s / h,   s = tau - t_n

F_law: eq. (18)-(19) (``law_kernel.evaluate``); omega_m: eq. (16) of the ring speeds at t_n; c_n, c*: the
component's force at both ends against the law (``begin``); g_k: the onset correction of substep k
(``onset_corrections``); the substeps from the stiffest law tangent met in the step (``substep_tangent``),
at least ``min_substeps`` in contact (``at_least``).

The scheme's state is one float64 array ``LM`` (layout ``LM_FIELDS``), the onset corrections an (m x 5) array
(g0_x, g0_y, g1_x, g1_y, present: g0 + g1 sigma over the substep) and the substep-start states of the pass an
((m + 1) x 4) array ``bounds`` (e_x, e_y, v_x, v_y): the next pass's onset corrections are built from them, and the
first pass's acceptance (``any_onset``, ``end_mismatch``) looks at them.
"""
from __future__ import annotations

import math

from numba import njit

from fmu_bearing.parameters import DAMPING_CONSTANT
from mechanism.cosim.law_kernel import HEADER, edge_tolerance, evaluate, sym_eig_max
from mechanism.multibody.kernels import (
    LEAF,
    _applied,
    _kinematics,
    _layout,
    _link_inputs,
    _rotations,
    _stage_row,
    _u,
    internal,
    max_violation,
    powers,
    prepare,
    stage_derivative,
    stage_inputs,
)

#: ``LM``: t_n, h, phi_n, omega_m, omega_inner and omega_outer at t_n, c_n (2), c* (2), the stiffest tangent's
#: largest eigenvalue and its K, C (6), the substeps of the last pass, ``resolution``, ``min_substeps``
LM_FIELDS = ("t", "h", "cage", "omega", "wi", "wo", "c0_x", "c0_y", "c1_x", "c1_y", "k_seen",
             "k_xx", "k_xy", "k_yy", "c_xx", "c_xy", "c_yy", "m", "resolution", "min_substeps")
LM_SIZE = len(LM_FIELDS)


@njit(**LEAF)
def law(LM, P, out, loads, s, e_x, e_y, v_x, v_y):
    """``LawModel._law``: F_law(e, v; phi_n + omega_m s) [N] (eq. 18-19) into out; keeps the stiffest tangent."""
    evaluate(P, e_x, e_y, v_x, v_y, LM[2] + LM[3] * s, LM[4], LM[5], out, loads)
    k = sym_eig_max(out[2], out[3], out[4])
    if k > LM[10]:
        LM[10] = k
        for i in range(6):
            LM[11 + i] = out[2 + i]
    return out[0], out[1]


@njit(**LEAF)
def set_cage(LM, P, cage, omega_inner, omega_outer):
    """``LawModel.set_cage``: phi_n [rad], omega_m (eq. 16) and the ring speeds [rad/s] at t_n."""
    LM[2] = cage
    LM[3] = omega_inner * P[11] + omega_outer * P[12]
    LM[4], LM[5] = omega_inner, omega_outer


@internal(LEAF)
def begin(LM, P, out, loads, a, x, have_trial, h):
    """``LawModel.begin_step`` from the start exchange a (13 fields of ``Exchanged``) and, if ``have_trial``, the
    last pass's end exchange x: a new step's stiffest tangent (the start's, the law at the predicted end), c_n
    and c* (c_n on the first pass)."""
    if not have_trial:
        LM[10] = sym_eig_max(a[7], a[8], a[9])
        for i in range(6):
            LM[11 + i] = a[7 + i]
        law(LM, P, out, loads, h, a[1] + h * a[3], a[2] + h * a[4], a[3], a[4])
    fx, fy = law(LM, P, out, loads, 0.0, a[1], a[2], a[3], a[4])
    LM[0] = a[0]
    LM[6], LM[7] = a[5] - fx, a[6] - fy
    if not have_trial:
        LM[8], LM[9] = LM[6], LM[7]
    else:
        fx, fy = law(LM, P, out, loads, x[0] - a[0], x[1], x[2], x[3], x[4])
        LM[8], LM[9] = x[5] - fx, x[6] - fy
    LM[1] = h


@njit(**LEAF)
def substep_tangent(LM, a, xs):
    """``LawModel.substep_tangent`` into xs: the start exchange a with the stiffest tangent met, K scaled by
    ``resolution``^2 and C by ``resolution``."""
    r = LM[18]
    r2 = r * r
    for i in range(7):
        xs[i] = a[i]
    for i in range(3):
        xs[7 + i] = r2 * LM[11 + i]
        xs[10 + i] = r * LM[14 + i]


@internal(LEAF)
def at_least(LM, m, cap):
    """``LawModel.set_substeps``' count: m, at least ``min_substeps`` (at most cap) once the law met a contact."""
    if LM[10] > 0.0 and m < LM[19]:
        m = max(m, min(int(LM[19]), cap))
    return m


@internal(LEAF)
def end_mismatch(LM, P, out, loads, b):
    """``LawModel.end_mismatch`` on the first pass: the end exchange b's force against the law there plus c_n."""
    evaluate(P, b[1], b[2], b[3], b[4], LM[2] + LM[3] * (b[0] - LM[0]), LM[4], LM[5], out, loads)
    return b[5] - (out[0] + LM[6]), b[6] - (out[1] + LM[7])


@internal(LEAF)
def any_onset(LM, P, m, bounds, end, onsets):
    """``LawModel.end_mismatch``'s condition: a contact onset to correct in this pass's substeps (``onsets`` is
    overwritten: the next pass builds its own)."""
    onset_corrections(LM, P, m, bounds, end, onsets)
    for k in range(m):
        if onsets[k, 4] != 0.0:
            return True
    return False


@njit(**LEAF)
def onset_fraction(da, db, ma, mb):
    """``law_model.onset_fraction``: the root theta in (0, 1] of the cubic Hermite interpolant of a ball's deflection
    through (da, ma) at the substep's start and (db, mb) at its end (slopes per substep), da <= 0 < db."""
    theta = da / (da - db)
    for _ in range(4):
        t2 = theta * theta
        t3 = t2 * theta
        p = (2.0 * t3 - 3.0 * t2 + 1.0) * da + (t3 - 2.0 * t2 + theta) * ma + (3.0 * t2 - 2.0 * t3) * db \
            + (t3 - t2) * mb
        dp = (6.0 * t2 - 6.0 * theta) * (da - db) + (3.0 * t2 - 4.0 * theta + 1.0) * ma + (3.0 * t2 - 2.0 * theta) * mb
        if not dp > 0.0:
            break
        nxt = theta - p / dp
        if not 0.0 < nxt <= 1.0:
            break
        theta = nxt
    return theta


@njit(**LEAF)
def onset_weights(theta, j, d):
    """``law_model.onset_weights``: (g0, g1) [N] of the correction g0 + g1 sigma over a substep (sigma = 0, 1/2,
    1/2, 1 at RK4's stages) for a ball force switched on at theta with the value j and the slope d per substep."""
    half = 1.0 if theta < 0.5 else 0.0
    r = 1.0 - theta
    fm = half * (j + d * (0.5 - theta))
    f1 = j + d * r
    a = j * r + d * r * r / 2.0 - (4.0 * fm + f1) / 6.0
    b = j * r * r / 2.0 + d * r * r * r / 6.0 - fm / 3.0
    return 6.0 * b - 2.0 * a, 6.0 * a - 12.0 * b


@njit(**LEAF)
def onset_corrections(LM, P, m, bounds, end, onsets):
    """``LawModel._onset_corrections`` into onsets[:m] (g0_x, g0_y, g1_x, g1_y, present): per substep the force
    g0 + g1 sigma that gives RK4 each contact onset's exact impulse and first moment (eq. 18), from the last
    pass's substep starts ``bounds`` and its end exchange ``end``."""
    for k in range(m):
        for i in range(5):
            onsets[k, i] = 0.0
    if int(P[3]) != DAMPING_CONSTANT or P[4] == 0.0:
        return
    nb = int(P[0])
    C, half, hs, om = P[4], P[2], LM[1] / m, LM[3]
    spacing = 2.0 * math.pi / nb
    # A ball's deflection at a substep's bound, first from the bound's cage angle rotated onto the ball's place (the
    # law's table: cos, sin of 2 pi r / nb, eq. 17), one cos and sin per bound: within |e| 1e-15 (8 + |angle|) of
    # the exact one below (the rounding of the angles and of a few products), far inside ``tol``. A ball clearly
    # loaded at the substep's start or clearly unloaded at its end has no onset there (the exact da, db have the
    # same signs) and needs no trig of its own; the others are decided by the exact arithmetic, as before.
    pb = LM[2]
    cb0, sb0 = math.cos(pb), math.sin(pb)
    for k in range(m):
        if k + 1 < m:
            bx, by, bvx, bvy = bounds[k + 1, 0], bounds[k + 1, 1], bounds[k + 1, 2], bounds[k + 1, 3]
        else:
            bx, by, bvx, bvy = end[1], end[2], end[3], end[4]
        ax, ay, avx, avy = bounds[k, 0], bounds[k, 1], bounds[k, 2], bounds[k, 3]
        pa, pb = LM[2] + om * k * hs, LM[2] + om * (k + 1) * hs
        ca0, sa0 = cb0, sb0
        cb0, sb0 = math.cos(pb), math.sin(pb)
        xa, ya = ax * ca0 + ay * sa0, ay * ca0 - ax * sa0          # e in the cage's frame at both bounds
        xb, yb = bx * cb0 + by * sb0, by * cb0 - bx * sb0
        tol_a = edge_tolerance(half, ax, ay, pa)
        tol_b = edge_tolerance(half, bx, by, pb)
        g0x = g0y = g1x = g1y = 0.0
        for r in range(nb):
            cr, sr = P[_u(HEADER + r)], P[_u(HEADER + nb + r)]
            if xa * cr + ya * sr - half > tol_a or xb * cr + yb * sr - half < -tol_b:
                continue                                            # loaded at the start, or unloaded at the end
            ca, sa = math.cos(pa + r * spacing), math.sin(pa + r * spacing)
            cb, sb = math.cos(pb + r * spacing), math.sin(pb + r * spacing)
            da, db = ax * ca + ay * sa - half, bx * cb + by * sb - half
            if not (da <= 0.0 and 0.0 < db):
                continue
            ma = (avx * ca + avy * sa + om * (ay * ca - ax * sa)) * hs
            mb = (bvx * cb + bvy * sb + om * (by * cb - bx * sb)) * hs
            theta = onset_fraction(da, db, ma, mb)
            phi = pa + r * spacing + theta * (pb - pa)
            ux, uy = math.cos(phi), math.sin(phi)
            wa = (avx * ux + avy * uy) * C
            wb = (bvx * ux + bvy * uy) * C
            j = wa + theta * (wb - wa)
            if not j > 0.0:
                continue
            g0, g1 = onset_weights(theta, j, wb - wa)
            g0x, g0y = g0x + g0 * ux, g0y + g0 * uy
            g1x, g1y = g1x + g1 * ux, g1y + g1 * uy
        if g0x != 0.0 or g0y != 0.0 or g1x != 0.0 or g1y != 0.0:
            onsets[k, 0], onsets[k, 1], onsets[k, 2], onsets[k, 3], onsets[k, 4] = g0x, g0y, g1x, g1y, 1.0


@njit(**LEAF)
def force(LM, P, out, loads, onsets, bounds, tau, e_x, e_y, v_x, v_y, sub, stage):
    """``LawModel.force`` at RK4 stage ``stage`` of substep ``sub``: the law, the onset correction, the ramp of
    the end corrections; records the substep's start state (stage 0)."""
    s = tau - LM[0]
    q = _u(sub)
    fx, fy = law(LM, P, out, loads, s, e_x, e_y, v_x, v_y)
    if stage == 0:
        bounds[q, 0], bounds[q, 1], bounds[q, 2], bounds[q, 3] = e_x, e_y, v_x, v_y
    if onsets[q, 4] != 0.0:
        sigma = 0.0 if stage == 0 else (1.0 if stage == 3 else 0.5)
        fx, fy = fx + (onsets[q, 0] + onsets[q, 2] * sigma), fy + (onsets[q, 1] + onsets[q, 3] * sigma)
    r = s / LM[1]
    return fx + LM[6] + r * (LM[8] - LM[6]), fy + LM[7] + r * (LM[9] - LM[7])


@internal(LEAF)
def advance(y, t0, hs, substeps, t_end, LM, P, out, loads, onsets, bounds, I, R, L, LR, W, u, acc, stages):
    """``kernels.advance`` (same arithmetic, the energy account's stages and powers) with the law-model's force
    at every stage, the first included (the master's RK4 calls ``force`` four times per substep), on y in place
    (allocating nothing: no reference counting around its calls; ``run_steps`` passes a copy); returns the end
    state's max |Phi| and whether it is finite. No wrapper around it: each level of compiled calls re-optimises
    and re-emits the machine code of everything below it (docs/kernels.md, "Fifth pass")."""
    N = y.shape[0]
    ork = _layout(I)[9]                  # in W: the four stages' dy/dt, the stage state, the stages' powers
    yt = W[ork + 4 * N:ork + 5 * N]
    opw = ork + 5 * N
    h2 = 0.5 * hs
    nb = I[0]
    for sub in range(substeps):
        t = t0 + sub * hs
        for st in range(4):
            k = W[ork + st * N:ork + (st + 1) * N]
            if st == 0:
                ts = t
                for i in range(N):
                    yt[_u(i)] = y[_u(i)]
            else:
                cs = h2 if st < 3 else hs                  # y + h/2 k1, y + h/2 k2, y + h k3
                ts = t + cs
                o = ork + (st - 1) * N
                for i in range(N):
                    yt[_u(i)] = y[_u(i)] + cs * W[_u(o + i)]
            if st == 0 and sub > 0 and L[0] == 1:
                _applied(I, R, W)         # the rotations and inputs of y: the last substep's end left them
            else:
                stage_inputs(yt, I, R, L, LR, W, u)
            fx, fy = force(LM, P, out, loads, onsets, bounds, ts, u[0], u[1], u[2], u[3], sub, st)
            stage_derivative(ts, yt, fx, fy, I, R, L, LR, W, u, k)
            o = opw + 3 * st
            W[_u(o)], W[_u(o + 1)], W[_u(o + 2)] = powers(yt, I, R, W)
            _stage_row(stages, 5 * sub + st, yt, u, nb, L)
        c = hs / 6.0
        for i in range(N):
            y[_u(i)] = y[_u(i)] + c * (W[_u(ork + i)] + 2.0 * (W[_u(ork + N + i)] + W[_u(ork + 2 * N + i)])
                                       + W[_u(ork + 3 * N + i)])
        for j in range(3):
            acc[j] += c * (W[_u(opw + j)] + 2.0 * (W[_u(opw + 3 + j)] + W[_u(opw + 6 + j)]) + W[_u(opw + 9 + j)])
        if L[0] == 1:
            _rotations(y, I, W)
            _link_inputs(y, I, L, LR, W, u)
        _stage_row(stages, 5 * sub + 4, y, u, nb, L)
    for i in range(N):
        if not math.isfinite(y[i]):
            return math.nan, False
    if L[0] == 1 and substeps > 0:     # ``prepare`` but the rotations and inputs of y, there since the last substep
        _kinematics(y, t_end, I, R, W)
    else:
        prepare(y, t_end, I, R, L, LR, W, u)
    return max_violation(I, W), True

