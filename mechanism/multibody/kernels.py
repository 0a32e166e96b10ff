"""Compiled (numba) kernels of the planar multibody solver: a second implementation of
:class:`mechanism.multibody.solver.System` for the per-step work, held against it by
tests/test_kernels.py (1e-12 in accelerations, 1e-9 over a 0.2-revolution trajectory).

The model reaches the kernels as data: ``pack(system)`` flattens what ``System`` precomputed
from a :class:`~mechanism.multibody.model.Model` into two arrays,

* ``I`` (int64): header ``[nb, n, m, K, A, 0, 0, 0]``, then bJ, bI, bref (K point rows each),
  aJ, aI (A angle rows each), to_model (m);
* ``R`` (float64): header ``[2 alpha, beta^2]``, then sJx, sJy, sIx, sIy, n'x, n'y, ref_is_I
  (K each), c0, omega (A each), 1/M (n), gravity forces (n), M (n);

so one set of kernels serves every planar model the data layer accepts (the slider-crank, the
four-bar, the double pendulum of ``mechanism.systems``). Body index ``nb`` is ground (zero
coordinates, no Jacobian columns). Rows are in the solver's internal order [point rows, angle
rows]; ``to_model`` maps multipliers to model order, as in ``System``.

A force joint (``BearingJoint``) reaches the step as ``L`` (int64: ``[present, housing body,
journal body, eq15]``) and ``LR`` (float64: ``[housing s'x, s'y, journal s'x, s'y, housing
radius, journal radius]``); its force over a communication step is a coupling scheme's
``ForceModel`` (17 coefficients, ``mechanism.cosim.coupling.base``).

The equations and their numbers are those of ``solver.py`` (Xu et al. 2012 eq. 3-9, Baumgarte
stabilisation) and ``mechanism.cosim.joint`` (eq. 10-12, 13-15, 20-23); see those modules for
the derivations. Every kernel is ``@njit(cache=True)``: compiled once per machine and kept on
disk next to this file (``__pycache__``).

Work arrays are preallocated by the caller (``Workspace``) so that a step allocates nothing
but its result.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

H_I = 8   # header length of I
H_R = 2   # header length of R


# ---------------------------------------------------------------------------------- packing
def pack(system) -> tuple[np.ndarray, np.ndarray]:
    """(I, R): the arrays the kernels read, from a NumPy ``System`` (see the module docstring)."""
    s = system
    nb = s.n // 3
    K, A, m, n = s._K, len(s._aJ), s.m, s.n
    ints = np.concatenate((np.array([nb, n, m, K, A, 0, 0, 0], np.int64), s._bJ, s._bI, s._bref, s._aJ, s._aI,
                           s._to_model)).astype(np.int64)
    reals = np.concatenate(([2.0 * s.alpha, s.beta * s.beta], s._sJ.real, s._sJ.imag, s._sI.real, s._sI.imag,
                            s._nprime.real, s._nprime.imag, s._ref_is_I, s._c0, s._omega, s._minv,
                            s._gravity_force, s.mass)).astype(np.float64)
    return ints, reals


def pack_link(system, joint=None, contact_points: str = "centres") -> tuple[np.ndarray, np.ndarray]:
    """(L, LR) of a bearing joint (``None``: no force joint)."""
    if joint is None:
        return np.zeros(4, np.int64), np.zeros(6, np.float64)
    nb = system.n // 3
    idx = {b.name: k for k, b in enumerate(system.model.bodies)}
    hb = idx.get(joint.housing.body, nb)
    jb = idx.get(joint.journal.body, nb)
    L = np.array([1, hb, jb, 1 if contact_points == "eq15" else 0], np.int64)
    LR = np.array([*joint.housing.local, *joint.journal.local, joint.housing_radius, joint.journal_radius],
                  np.float64)
    return L, LR


def workspace_size(ints: np.ndarray) -> int:
    nb, n, m = int(ints[0]), int(ints[1]), int(ints[2])
    return m * n + 5 * m + m * m + 2 * n + 10 * n + 2 * (nb + 1)


# ---------------------------------------------------------------------------------- kinematics
@njit(cache=True)
def _slices(I, W):
    n, m = I[1], I[2]
    o = 0
    J = W[o:o + m * n].reshape((m, n))
    o += m * n
    phi = W[o:o + m]
    o += m
    gam = W[o:o + m]
    o += m
    rhs = W[o:o + m]
    o += m
    lam = W[o:o + m]
    o += m
    phit = W[o:o + m]
    o += m
    S = W[o:o + m * m].reshape((m, m))
    o += m * m
    Q = W[o:o + n]
    o += n
    tmp = W[o:o + n]
    o += n
    return J, phi, gam, rhs, lam, phit, S, Q, tmp


@njit(cache=True)
def _rotations(q, I, W):
    """cos and sin of every body's angle (ground: 1, 0), once per state, in W after the other slices."""
    nb, n, m = I[0], I[1], I[2]
    o = m * n + 5 * m + m * m + 2 * n
    cs = W[o:o + 2 * (nb + 1)].reshape((nb + 1, 2))
    for b in range(nb):
        cs[b, 0] = math.cos(q[3 * b + 2])
        cs[b, 1] = math.sin(q[3 * b + 2])
    cs[nb, 0] = 1.0
    cs[nb, 1] = 0.0
    return cs


@njit(cache=True)
def _body_point_cs(q, qd, nb, b, sx, sy, c, s):
    """(omega, u_x, u_y, x, y, xd, yd): u = A s' of a point on body b (eq. 10) and the body's state,
    given c, s = cos, sin of its angle; ground (b = nb): u = s', the rest 0."""
    if b >= nb:
        return 0.0, sx, sy, 0.0, 0.0, 0.0, 0.0
    return qd[3 * b + 2], c * sx - s * sy, s * sx + c * sy, q[3 * b], q[3 * b + 1], qd[3 * b], qd[3 * b + 1]


@njit(cache=True)
def _body_point(q, qd, nb, b, sx, sy):
    """``_body_point_cs`` computing the body's cos, sin itself."""
    if b >= nb:
        return 0.0, sx, sy, 0.0, 0.0, 0.0, 0.0
    th = q[3 * b + 2]
    return _body_point_cs(q, qd, nb, b, sx, sy, math.cos(th), math.sin(th))


@njit(cache=True)
def kinematics(q, qd, t, I, R, W, J, phi, gam, phit):
    """Phi (eq. 3), Phi_q, gamma (eq. 5) and Phi_t (eq. 4) in internal row order, written in place."""
    nb, n, m, K, A = I[0], I[1], I[2], I[3], I[4]
    bJ = I[H_I:H_I + K]
    bI = I[H_I + K:H_I + 2 * K]
    bref = I[H_I + 2 * K:H_I + 3 * K]
    aJ = I[H_I + 3 * K:H_I + 3 * K + A]
    aI = I[H_I + 3 * K + A:H_I + 3 * K + 2 * A]
    o = H_R
    sJx, sJy = R[o:o + K], R[o + K:o + 2 * K]
    sIx, sIy = R[o + 2 * K:o + 3 * K], R[o + 3 * K:o + 4 * K]
    npx, npy = R[o + 4 * K:o + 5 * K], R[o + 5 * K:o + 6 * K]
    refI = R[o + 6 * K:o + 7 * K]
    c0 = R[o + 7 * K:o + 7 * K + A]
    om = R[o + 7 * K + A:o + 7 * K + 2 * A]
    J[:, :] = 0.0
    cs = _rotations(q, I, W)
    for k in range(K):
        j, i, r = bJ[k], bI[k], bref[k]
        # u = A s' (eq. 10) of each point, its body's position, velocity and angular velocity
        wj, ujx, ujy, zjx, zjy, zdjx, zdjy = _body_point_cs(q, qd, nb, j, sJx[k], sJy[k], cs[j, 0], cs[j, 1])
        wi, uix, uiy, zix, ziy, zdix, zdiy = _body_point_cs(q, qd, nb, i, sIx[k], sIy[k], cs[i, 0], cs[i, 1])
        dx = (zjx - zix) + (ujx - uix)                     # d = r_J^P - r_I^P
        dy = (zjy - ziy) + (ujy - uiy)
        wujx, wujy = wj * ujx, wj * ujy
        wuix, wuiy = wi * uix, wi * uiy
        dcx = wj * wujx - wi * wuix                        # -(relative centripetal acceleration)
        dcy = wj * wujy - wi * wuiy
        # n = A_ref n'; cn = conj(n)
        if r < nb and refI[k] != 0.0:
            cr, sr = cs[r, 0], cs[r, 1]
            nx, ny = cr * npx[k] - sr * npy[k], sr * npx[k] + cr * npy[k]
            wr = qd[3 * r + 2]
        else:
            nx, ny = npx[k], npy[k]
            wr = 0.0
        cnx, cny = nx, -ny
        p = cnx * dx - cny * dy                            # Re(conj(n) d), eq. (3)
        phi[k] = p
        if wr != 0.0 or refI[k] != 0.0:
            ddx = (zdjx - zdix) - (wujy - wuiy)            # relative point velocity
            ddy = (zdjy - zdiy) + (wujx - wuix)
            ax = dcx - 2.0 * wr * ddy                      # dcen + 2 i wr dd
            ay = dcy + 2.0 * wr * ddx
            gam[k] = wr * wr * p + (cnx * ax - cny * ay)   # eq. (5), n turning with body I
        else:
            gam[k] = cnx * dcx - cny * dcy                 # eq. (5), fixed n
        phit[k] = 0.0
        # Phi_q = Re(conj(n) G): x -> 1, y -> i, theta -> i u (J), minus for I, plus the turning n
        if j < nb:
            J[k, 3 * j] += cnx
            J[k, 3 * j + 1] += -cny
            J[k, 3 * j + 2] += -(cnx * ujy + cny * ujx)    # Re(cn * i uJ)
        if i < nb:
            J[k, 3 * i] += -cnx
            J[k, 3 * i + 1] += cny
            gx = uix + refI[k] * dx
            gy = uiy + refI[k] * dy
            J[k, 3 * i + 2] += cnx * gy + cny * gx         # Re(cn * (-i g))
    for a in range(A):
        row = K + a
        j, i = aJ[a], aI[a]
        thj = q[3 * j + 2] if j < nb else 0.0
        thi = q[3 * i + 2] if i < nb else 0.0
        phi[row] = thj - thi - (c0[a] + om[a] * t)
        gam[row] = 0.0
        phit[row] = -om[a]
        if j < nb:
            J[row, 3 * j + 2] += 1.0
        if i < nb:
            J[row, 3 * i + 2] -= 1.0


@njit(cache=True)
def _cholesky_solve(S, b):
    """Solve S x = b in place in b (S symmetric positive semidefinite, overwritten by its factor).

    A pivot below 1e-12 of the largest diagonal entry (a redundant constraint) is dropped: that
    unknown is set to 0, which solves a consistent redundant system (a basic, not the minimum-norm,
    solution; the accelerations M^-1 (Q - Phi_q^T lam) are the same). Returns the number of
    dropped pivots."""
    m = S.shape[0]
    big = 0.0
    for j in range(m):
        big = max(big, abs(S[j, j]))
    tol = 1e-12 * big
    dropped = 0
    for j in range(m):
        d = S[j, j]
        for k in range(j):
            d -= S[j, k] * S[j, k]
        if not d > tol:
            dropped += 1
            for i in range(j, m):
                S[i, j] = 0.0
            continue
        d = math.sqrt(d)
        S[j, j] = d
        for i in range(j + 1, m):
            s = S[i, j]
            for k in range(j):
                s -= S[i, k] * S[j, k]
            S[i, j] = s / d
    for i in range(m):
        if S[i, i] == 0.0:
            b[i] = 0.0
            continue
        s = b[i]
        for k in range(i):
            s -= S[i, k] * b[k]
        b[i] = s / S[i, i]
    for i in range(m - 1, -1, -1):
        if S[i, i] == 0.0:
            b[i] = 0.0
            continue
        s = b[i]
        for k in range(i + 1, m):
            s -= S[k, i] * b[k]
        b[i] = s / S[i, i]
    return dropped


@njit(cache=True)
def solve(qd, Q, I, R, W, qdd):
    """Eq. (9) with Baumgarte's gamma* for kinematics already in W: qdd (written) and lambda
    (internal order, left in W). (Phi_q M^-1 Phi_q^T) lam = Phi_q M^-1 Q - gamma*, qdd = M^-1 (Q - Phi_q^T lam)."""
    n, m, K, A = I[1], I[2], I[3], I[4]
    o = H_R + 7 * K + 2 * A
    minv = R[o:o + n]
    a2, b2 = R[0], R[1]
    J, phi, gam, rhs, lam, phit, S, _, tmp = _slices(I, W)
    for i in range(n):
        tmp[i] = minv[i] * Q[i]
    for r in range(m):
        s = 0.0
        pd = 0.0
        for i in range(n):
            s += J[r, i] * tmp[i]
            pd += J[r, i] * qd[i]
        rhs[r] = s - gam[r] + a2 * (pd + phit[r]) + b2 * phi[r]
        for c in range(r + 1):
            v = 0.0
            for i in range(n):
                v += J[r, i] * minv[i] * J[c, i]
            S[r, c] = v
            S[c, r] = v
    for r in range(m):
        lam[r] = rhs[r]
    if m > 0:
        _cholesky_solve(S, lam)                            # redundant rows dropped (see there)
    for i in range(n):
        v = tmp[i]
        for r in range(m):
            v -= minv[i] * J[r, i] * lam[r]
        qdd[i] = v


@njit(cache=True)
def accelerations(q, qd, t, Q, I, R, W, qdd):
    """Kinematics and eq. (9) for the state (q, qd, t) and applied forces Q: qdd written, lambda in W."""
    J, phi, gam, _, _, phit, _, _, _ = _slices(I, W)
    kinematics(q, qd, t, I, R, W, J, phi, gam, phit)
    solve(qd, Q, I, R, W, qdd)


@njit(cache=True)
def multipliers(I, W, lam_model):
    """Lambda of the last solve, in model order."""
    m, K, A = I[2], I[3], I[4]
    to_model = I[H_I + 3 * K + 2 * A:H_I + 3 * K + 2 * A + m]
    lam = _slices(I, W)[4]
    for k in range(m):
        lam_model[k] = lam[to_model[k]]


@njit(cache=True)
def max_violation(I, W):
    """max |Phi| of the last kinematics evaluation [m or rad]."""
    phi = _slices(I, W)[1]
    v = 0.0
    for k in range(phi.shape[0]):
        a = abs(phi[k])
        if a > v:
            v = a
    return v


# ---------------------------------------------------------------------------------- force joint
@njit(cache=True)
def _point(q, qd, nb, b, sx, sy):
    """(x, y, xd, yd) of a point s' on body b (eq. 10-12); ground: (s', 0)."""
    w, ux, uy, x, y, xd, yd = _body_point(q, qd, nb, b, sx, sy)
    return x + ux, y + uy, xd - w * uy, yd + w * ux


@njit(cache=True)
def link_inputs(q, qd, nb, L, LR, u):
    """The bearing's inputs (e_x, e_y, v_x, v_y, omega_inner, omega_outer), eq. (10)-(12), into u."""
    hb, jb = L[1], L[2]
    xi, yi, vxi, vyi = _point(q, qd, nb, hb, LR[0], LR[1])
    xj, yj, vxj, vyj = _point(q, qd, nb, jb, LR[2], LR[3])
    u[0] = xj - xi
    u[1] = yj - yi
    u[2] = vxj - vxi
    u[3] = vyj - vyi
    u[4] = qd[3 * jb + 2] if jb < nb else 0.0
    u[5] = qd[3 * hb + 2] if hb < nb else 0.0


@njit(cache=True)
def _add_point_force(Q, q, nb, b, sx, sy, fx, fy, at, ax, ay):
    if b >= nb:
        return
    i = 3 * b
    if not at:
        th = q[i + 2]
        c, s = math.cos(th), math.sin(th)
        ax = q[i] + (c * sx - s * sy)
        ay = q[i + 1] + (s * sx + c * sy)
    Q[i] += fx
    Q[i + 1] += fy
    Q[i + 2] += (ax - q[i]) * fy - (ay - q[i + 1]) * fx


@njit(cache=True)
def add_link_force(Q, q, nb, L, LR, ex, ey, fx, fy):
    """Generalized forces of F on the housing body and -F on the journal body, eq. (20)-(23)."""
    hb, jb = L[1], L[2]
    if L[3] == 1:                                         # eq. (14)-(15): at the contact points
        e = math.hypot(ex, ey)
        if e > 0.0:
            nx, ny = ex / e, ey / e
            xi, yi, _, _ = _point(q, q, nb, hb, LR[0], LR[1])
            xj, yj, _, _ = _point(q, q, nb, jb, LR[2], LR[3])
            _add_point_force(Q, q, nb, hb, LR[0], LR[1], fx, fy, True, xi + LR[4] * nx, yi + LR[4] * ny)
            _add_point_force(Q, q, nb, jb, LR[2], LR[3], -fx, -fy, True, xj + LR[5] * nx, yj + LR[5] * ny)
            return
    _add_point_force(Q, q, nb, hb, LR[0], LR[1], fx, fy, False, 0.0, 0.0)
    _add_point_force(Q, q, nb, jb, LR[2], LR[3], -fx, -fy, False, 0.0, 0.0)


@njit(cache=True)
def force_of_model(fm, tau, ex, ey, vx, vy):
    """F(tau, e, v) = F0 + a1 s + a2 s^2 + K (e - e0) + C (v - v0) (``ForceModel``)."""
    s = tau - fm[0]
    dx, dy, dvx, dvy = ex - fm[7], ey - fm[8], vx - fm[9], vy - fm[10]
    return (fm[1] + s * (fm[3] + s * fm[5]) + fm[11] * dx + fm[12] * dy + fm[14] * dvx + fm[15] * dvy,
            fm[2] + s * (fm[4] + s * fm[6]) + fm[12] * dx + fm[13] * dy + fm[15] * dvx + fm[16] * dvy)


# ---------------------------------------------------------------------------------- the step
@njit(cache=True)
def applied(q, I, R, Q):
    """Q^A of gravity [N, N, N m] into Q."""
    n, K, A = I[1], I[3], I[4]
    o = H_R + 7 * K + 2 * A + n
    for i in range(n):
        Q[i] = R[o + i]


@njit(cache=True)
def rhs(tau, y, fm, I, R, L, LR, W, u, dy):
    """dy/dt = [qd, qdd] with the force joint's force given by the force model fm."""
    n = I[1]
    q, qd = y[:n], y[n:]
    Q = _slices(I, W)[7]
    applied(q, I, R, Q)
    if L[0] == 1:
        link_inputs(q, qd, I[0], L, LR, u)
        fx, fy = force_of_model(fm, tau, u[0], u[1], u[2], u[3])
        add_link_force(Q, q, I[0], L, LR, u[0], u[1], fx, fy)
    dy[:n] = qd
    accelerations(q, qd, tau, Q, I, R, W, dy[n:])


@njit(cache=True)
def powers(y, I, R, W):
    """The powers [W] at the state y whose right-hand side was just evaluated (kinematics, lambda and Q in W):
    of the drivers lambda . Phi_t (the rheonomic constraints' work, e.g. the crank's M omega), of the applied
    forces Q^A . q' and of the force joint Q_link . q' (Q minus Q^A: the bearing force's work on the mechanism).
    With the velocity constraints met, dT/dt is their sum (eq. 4, 7, 9); the energy account integrates them
    with the RK4 stages (``advance``)."""
    n, m, K, A = I[1], I[2], I[3], I[4]
    ol = m * n + 3 * m                     # lambda, Phi_t and Q in W (the layout of _slices)
    oq = m * n + 5 * m + m * m
    drive = 0.0
    for r in range(m):
        drive += W[ol + r] * W[ol + m + r]
    o = H_R + 7 * K + 2 * A + n
    app = 0.0
    total = 0.0
    for i in range(n):
        app += R[o + i] * y[n + i]
        total += W[oq + i] * y[n + i]
    return drive, app, total - app


@njit(cache=True)
def _stage_row(stages, row, y, u, nb, L):
    """The energy account's record of a stage state: its bearing inputs u and the ring angles (journal, housing)."""
    n = y.shape[0] // 2
    for i in range(6):
        stages[row, i] = u[i]
    stages[row, 6] = y[3 * L[2] + 2] if L[2] < nb else 0.0
    stages[row, 7] = y[3 * L[1] + 2] if L[1] < nb else 0.0


@njit(cache=True)
def advance(y, t0, hs, substeps, t_end, fm, k1, k1_valid, I, R, L, LR, W, u, acc=None, p1=None, stages=None):
    """``substeps`` RK4 steps of size hs from (t0, y) under the force model fm; returns the new state
    its constraint violation max |Phi| (one kinematics evaluation per state) and whether it is finite.

    k1: dy/dt at (t0, y) if ``k1_valid`` (the end-of-step evaluation of the previous step, shared).
    On return W holds the kinematics of the end state at t_end (= t0 + substeps * hs, as the caller
    counts time) (for ``max_violation``
    and ``finish``) and u its bearing inputs. Same arithmetic as ``integrators.rk4_step``.

    Energy account (all three given, else skipped): ``acc`` (3) += the integrals over the step of the
    ``powers`` (drivers, applied, force joint) by the RK4 stages' own weights (the quadrature that RK4 applies
    to a state whose derivative they are); ``p1``: the powers at (t0, y) when ``k1_valid`` (from ``finish``);
    ``stages`` (5 substeps x 8): per substep, rows of its four stage states and its end state (``_stage_row``),
    for the bearing side of the account (``mechanism.cosim.energy``).
    """
    N = y.shape[0]
    n = N // 2
    k2 = np.empty(N)
    k3 = np.empty(N)
    k4 = np.empty(N)
    kk = np.empty(N)
    yt = np.empty(N)
    y = y.copy()
    h2 = 0.5 * hs
    account = acc is not None and p1 is not None and stages is not None
    nb = I[0]
    a1 = b1 = c1 = a2 = b2 = c2 = a3 = b3 = c3 = a4 = b4 = c4 = 0.0
    for sub in range(substeps):
        t = t0 + sub * hs
        if sub > 0 or not k1_valid:
            rhs(t, y, fm, I, R, L, LR, W, u, kk)
            if account:
                a1, b1, c1 = powers(y, I, R, W)
        else:
            kk[:] = k1
            if account:
                a1, b1, c1 = p1[0], p1[1], p1[2]
                if L[0] == 1:
                    link_inputs(y[:n], y[n:], nb, L, LR, u)
        if account:
            _stage_row(stages, 5 * sub, y, u, nb, L)
        for i in range(N):
            yt[i] = y[i] + h2 * kk[i]
        rhs(t + h2, yt, fm, I, R, L, LR, W, u, k2)
        if account:
            a2, b2, c2 = powers(yt, I, R, W)
            _stage_row(stages, 5 * sub + 1, yt, u, nb, L)
        for i in range(N):
            yt[i] = y[i] + h2 * k2[i]
        rhs(t + h2, yt, fm, I, R, L, LR, W, u, k3)
        if account:
            a3, b3, c3 = powers(yt, I, R, W)
            _stage_row(stages, 5 * sub + 2, yt, u, nb, L)
        for i in range(N):
            yt[i] = y[i] + hs * k3[i]
        rhs(t + hs, yt, fm, I, R, L, LR, W, u, k4)
        if account:
            a4, b4, c4 = powers(yt, I, R, W)
            _stage_row(stages, 5 * sub + 3, yt, u, nb, L)
        c = hs / 6.0
        for i in range(N):
            y[i] = y[i] + c * (kk[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
        if account:
            acc[0] += c * (a1 + 2.0 * (a2 + a3) + a4)
            acc[1] += c * (b1 + 2.0 * (b2 + b3) + b4)
            acc[2] += c * (c1 + 2.0 * (c2 + c3) + c4)
            if L[0] == 1:
                link_inputs(y[:n], y[n:], nb, L, LR, u)
            _stage_row(stages, 5 * sub + 4, y, u, nb, L)
    finite = True
    for i in range(N):
        if not math.isfinite(y[i]):
            finite = False
            break
    if finite:
        prepare(y, t_end, I, R, L, LR, W, u)
        return y, max_violation(I, W), True
    return y, math.nan, False


@njit(cache=True)
def prepare(y, t, I, R, L, LR, W, u):
    """Kinematics of the state y at t into W and its bearing inputs into u (the tail of ``advance``)."""
    n = I[1]
    J, phi, gam, _, _, phit, _, _, _ = _slices(I, W)
    kinematics(y[:n], y[n:], t, I, R, W, J, phi, gam, phit)
    if L[0] == 1:
        link_inputs(y[:n], y[n:], I[0], L, LR, u)


@njit(cache=True)
def finish(y, ex, ey, fx, fy, I, R, L, LR, W, u, dy, lam, row, probes, scale, t, cv, react, p1=None):
    """dy/dt = [qd, qdd] and lambda (model order) at the end state y whose kinematics ``advance``
    (or ``prepare``) left in W (and its bearing inputs in u), with the exchanged force (fx, fy) at
    inputs e. This is the recorded
    sample and the next step's first RK4 stage. If ``row`` is not empty the sample's probes are
    written into it (``fill_row``); with ``react`` = [first row, end row, x column, y column] of a
    kinematic joint (model order) and no force joint, the force written is that joint's reaction
    Q^C = -Phi_q^T lambda (eq. 7) on those coordinates (the ideal joint's force on the housing body).
    ``p1`` (energy account), if given, receives the ``powers`` there (the next step's first stage)."""
    n = I[1]
    q, qd = y[:n], y[n:]
    Q = _slices(I, W)[7]
    applied(q, I, R, Q)
    if L[0] == 1:
        add_link_force(Q, q, I[0], L, LR, ex, ey, fx, fy)
    dy[:n] = qd
    solve(qd, Q, I, R, W, dy[n:])
    multipliers(I, W, lam)
    if p1 is not None:
        p1[0], p1[1], p1[2] = powers(y, I, R, W)
    if row.shape[0] > 0 and L[0] == 0 and react.shape[0] == 4:
        m, K, A = I[2], I[3], I[4]
        to_model = I[H_I + 3 * K + 2 * A:H_I + 3 * K + 2 * A + m]
        J = _slices(I, W)[0]
        fx = fy = 0.0
        for r in range(react[0], react[1]):
            fx -= J[to_model[r], react[2]] * lam[r]
            fy -= J[to_model[r], react[3]] * lam[r]
    if row.shape[0] > 0:
        fill_row(row, probes, scale, y, dy, lam, u, fx, fy, t, cv, kinetic_energy(qd, I, R), n)


@njit(cache=True)
def fill_row(row, probes, scale, y, dy, lam, u, fx, fy, t, cv, ke, n):
    """Write the probes of a sample: row[probes[k, 0]] = scale[k] * source[probes[k, 2]] with source
    probes[k, 1]: 0 q, 1 qd, 2 qdd, 3 lambda (model order), 4 bearing inputs of y, 5 force (index 0 x,
    1 y), 6 time, 7 max |Phi| (cv), 8 kinetic energy (ke)."""
    for k in range(probes.shape[0]):
        c, s, i = probes[k, 0], probes[k, 1], probes[k, 2]
        if s == 0:
            v = y[i]
        elif s == 1:
            v = y[n + i]
        elif s == 2:
            v = dy[n + i]
        elif s == 3:
            v = lam[i]
        elif s == 4:
            v = u[i]
        elif s == 5:
            v = fx if i == 0 else fy
        elif s == 6:
            v = t
        elif s == 7:
            v = cv
        else:
            v = ke
        row[c] = scale[k] * v


@njit(cache=True)
def kinetic_energy(qd, I, R):
    """T = qd^T M qd / 2 [J]."""
    n, K, A = I[1], I[3], I[4]
    o = H_R + 7 * K + 2 * A + 2 * n
    T = 0.0
    for i in range(n):
        T += R[o + i] * (qd[i] * qd[i])
    return 0.5 * T
