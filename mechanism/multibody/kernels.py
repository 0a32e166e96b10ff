"""Compiled (numba) kernels of the planar multibody solver: a second implementation of
:class:`mechanism.multibody.solver.System` for the per-step work, held against it by
tests/test_kernels.py (1e-12 in accelerations, 1e-9 over a 0.2-revolution trajectory).

The model reaches the kernels as data: ``pack(system)`` flattens what ``System`` precomputed
from a :class:`~mechanism.multibody.model.Model` into two arrays,

* ``I`` (int64): header ``[nb, n, m, K, A, d, 0, 0]``, then bJ, bI, bref (K point rows each),
  aJ, aI (A angle rows each), to_model (m), then at ``d`` a directory (``H_D`` entries: where each list
  starts, and the number of S entries) and the sparsity of eq. (9) fixed by the model (``_structure``): the
  columns each row of Phi_q can fill (CSR, ascending), the rows each column holds (CSC), the entries of
  S = Phi_q M^-1 Phi_q^T that the factorisation reads (rows, columns, and the columns each shares), the
  symbolic Cholesky factor of S in the rows' order (L's rows and columns) and, per entry of L, the k < j
  with L[i, k] L[j, k] != 0. The prefix up to to_model is the previous layout (code compiled against it,
  e.g. a numba cache of a caller, reads it unchanged);
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
the derivations. Every kernel is ``@njit(**KERNEL)`` (or ``LEAF``; ``internal`` for those only compiled code calls):
compiled once per machine and kept on disk (``mechanism.kernel_cache``). The kernels that allocate nothing (``LEAF``) are compiled without
numba's reference counting, and the hot ones index with unsigned indices (``_u``): both only remove work around
the arithmetic (atomic increments around each call, the wraparound of a negative index on each access), the
numbers are the same bit for bit (the headline's outputs compare equal with ``cmp``).

Work arrays are preallocated by the caller (``Workspace``: ``np.zeros(workspace_size(I))``) so that a
step allocates nothing but its result. The kernels address it by offsets (``_layout``), not views: Phi_q
(m x n, row-major), Phi, gamma, the right-hand side and lambda of eq. (9), Phi_t (m each), the Schur
complement Phi_q M^-1 Phi_q^T and its factor (m x m), Q, M^-1 Q (n each), cos and sin of every body's
angle (2 (nb + 1)), the RK4 stages, the stage state (5 x 2n) and the stages' powers (4 x 3).

Sparsity: the products with Phi_q (the Schur complement, its right-hand side, Phi_q^T lambda) and the
Cholesky factorisation and solves of S visit only the structurally non-zero entries, in ascending order,
so every sum adds the same non-zero terms in the same order as the dense loops: the results are those of
the dense evaluation bit for bit (the skipped terms are exact zeros; tests/test_rhs_kernel.py holds the
pattern against the NumPy system's non-zeros).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.core.registry import CPUDispatcher

#: the options of every kernel: cached on disk, and without the C-callable wrapper numba otherwise generates with
#: each compiled function (``no_cfunc_wrapper``: it serves passing a kernel as a first-class function value, which
#: nothing here does, and cost its share of a first run's compile; the kernel's own code is the same)
KERNEL = {"cache": True, "no_cfunc_wrapper": True}
#: the options of the kernels that allocate nothing: also compiled without numba's reference counting (``_nrt``), so
#: that a call passes its arrays without the atomic increments and decrements around it (a tenth of the law-model
#: step's time when they were counted; the arithmetic is the same)
LEAF = {**KERNEL, "_nrt": False}


class CompiledOnly(CPUDispatcher):
    """A kernel compiled without numba's CPython wrapper (``internal``): compiled code calls it as any kernel; a call
    from Python, which would jump to a wrapper that does not exist, is refused here."""

    def __call__(self, *args, **kwargs):
        raise TypeError(f"{self.py_func.__module__}.{self.py_func.__qualname__} is called from compiled kernels only "
                        "(it has no Python entry: mechanism.multibody.kernels.internal)")


def internal(options: dict):
    """``@njit(**options)`` for a kernel that only other kernels call (none from Python, tests included): compiled
    without the CPython wrapper (numba's ``no_cpython_wrapper``, as numba's own internal kernels are). The wrapper
    unboxes every argument from Python objects; for the helpers of the step, with up to 20 arrays, those wrappers
    were about a tenth of a first run's compile (docs/kernels.md, "Fifth pass"). The dispatcher becomes a
    ``CompiledOnly``, which refuses a call from Python with a TypeError instead of crashing the interpreter."""
    def decorate(func):
        dispatcher = njit(**options, no_cpython_wrapper=True)(func)
        if isinstance(dispatcher, CPUDispatcher):   # not under NUMBA_DISABLE_JIT (a plain function then)
            dispatcher.__class__ = CompiledOnly
        return dispatcher
    return decorate

H_I = 8   # header length of I
H_D = 16  # length of the directory of the sparsity lists in I
H_R = 2   # header length of R


# ---------------------------------------------------------------------------------- packing
def _structure(nb: int, n: int, bJ, bI, aJ, aI) -> list[list[int]]:
    """The sparsity of eq. (9)'s products, fixed by the model (see the module docstring), as the lists
    [row pointers, columns, column pointers, rows, S rows, S columns, S pointers, S terms, L row pointers,
    L row entries, L column pointers, L column entries, common pointers, common entries]."""
    rows = [sorted({3 * b + d for b in (j, i) if b < nb for d in range(3)}) for j, i in zip(bJ, bI)]
    rows += [sorted({3 * b + 2 for b in (j, i) if b < nb}) for j, i in zip(aJ, aI)]
    m = len(rows)
    cols = [[r for r in range(m) if c in rows[r]] for c in range(n)]
    # S = Phi_q M^-1 Phi_q^T: rows r, c share a column; the symbolic Cholesky of S in the rows' order:
    # L[i, j] != 0 if S[i, j] != 0 or L[i, k] L[j, k] != 0 for a k < j
    terms = {(r, c): sorted(set(rows[r]) & set(rows[c])) for r in range(m) for c in range(r)}
    lower: list[set[int]] = [set() for _ in range(m)]        # lower[i]: the k < i with L[i, k] != 0
    for j in range(m):
        for i in range(j + 1, m):
            if terms[i, j] or lower[i] & lower[j]:
                lower[i].add(j)
    # the entries of S that the factorisation reads: L's pattern (fill-in included: S = 0 there) and the diagonal
    spairs = [(r, c, terms[r, c] if c < r else rows[r]) for r in range(m) for c in range(r + 1)
              if c == r or c in lower[r]]
    lrow = [sorted(x) for x in lower]
    lcol = [[i for i in range(m) if j in lower[i]] for j in range(m)]
    common = [sorted(lower[i] & lower[j]) for j in range(m) for i in lcol[j]]

    def csr(lists):
        ptr = [0]
        for x in lists:
            ptr.append(ptr[-1] + len(x))
        return ptr, [v for x in lists for v in x]

    out = [*csr(rows), *csr(cols), [p[0] for p in spairs], [p[1] for p in spairs], *csr([p[2] for p in spairs])]
    return out + [*csr(lrow), *csr(lcol), *csr(common)]


def pack(system) -> tuple[np.ndarray, np.ndarray]:
    """(I, R): the arrays the kernels read, from a NumPy ``System`` (see the module docstring)."""
    s = system
    nb = s.n // 3
    K, A, m, n = s._K, len(s._aJ), s.m, s.n
    rows = [s._bJ, s._bI, s._bref, s._aJ, s._aI, s._to_model]
    structure = _structure(nb, n, s._bJ, s._bI, s._aJ, s._aI)
    header = np.array([nb, n, m, K, A, H_I + 3 * K + 2 * A + m, 0, 0], np.int64)
    directory = np.zeros(H_D, np.int64)       # after to_model: where each list of _structure starts
    o = header[5] + H_D
    for k, part in enumerate(structure):
        directory[k] = o
        o += len(part)
    directory[14] = len(structure[4])          # entries of S's pattern
    ints = np.concatenate([header] + [np.asarray(p, np.int64) for p in rows] + [directory]
                          + [np.asarray(p, np.int64) for p in structure]).astype(np.int64)
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
    """Length of the work array W of a model packed as ``ints`` (the layout of ``_layout``)."""
    nb, n, m = int(ints[0]), int(ints[1]), int(ints[2])
    return m * n + 5 * m + m * m + 2 * n + 2 * (nb + 1) + 10 * n + 12


#: an index (never negative here) as unsigned, ``_u(i)``: numba then indexes an array without the wraparound of a
#: negative index (a shift, a mask and an add on every access; half the time of ``_solve`` where they were counted).
#: The hot kernels index with it; the values read and written are the same. A cast, not a function: nothing to
#: inline (an ``inline="always"`` helper at each of its call sites cost seconds of the first run's compile).
_u = np.uint64


@internal(LEAF)
def _layout(I):
    """Offsets in W: (phi, gamma, rhs, lambda, Phi_t, S, Q, M^-1 Q, cos/sin, RK4 stages); Phi_q is at 0."""
    nb, n, m = I[0], I[1], I[2]
    ophi = m * n
    oS = ophi + 5 * m
    oQ = oS + m * m
    ocs = oQ + 2 * n
    return ophi, ophi + m, ophi + 2 * m, ophi + 3 * m, ophi + 4 * m, oS, oQ, oQ + n, ocs, ocs + 2 * (nb + 1)


# ---------------------------------------------------------------------------------- kinematics
@njit(**LEAF)
def _rotations(y, I, W):
    """cos and sin of every body's angle (ground: 1, 0) into W, once per state."""
    nb = I[0]
    o = _layout(I)[8]
    for b in range(nb):
        th = y[_u(3 * b + 2)]
        W[_u(o + 2 * b)] = math.cos(th)
        W[_u(o + 2 * b + 1)] = math.sin(th)
    W[_u(o + 2 * nb)] = 1.0
    W[_u(o + 2 * nb + 1)] = 0.0


@internal(LEAF)
def _body_point(y, n, nb, b, sx, sy, c, s):
    """(omega, u_x, u_y, x, y, xd, yd): u = A s' of a point on body b (eq. 10) and the body's state
    (q = y[:n], qd = y[n:]), given c, s = cos, sin of its angle; ground (b = nb): u = s', the rest 0."""
    if b >= nb:
        return 0.0, sx, sy, 0.0, 0.0, 0.0, 0.0
    o, v = 3 * b, n + 3 * b                              # (int64 + uint64 is a float in numba: _u last)
    return (y[_u(v + 2)], c * sx - s * sy, s * sx + c * sy, y[_u(o)], y[_u(o + 1)], y[_u(v)], y[_u(v + 1)])


@internal(LEAF)
def _kinematics(y, t, I, R, W):
    """Phi (eq. 3), Phi_q, gamma (eq. 5) and Phi_t (eq. 4) of the state y = [q, qd] in internal row order,
    written in W; the rotations (``_rotations``) of y must be in W."""
    nb, n, m, K, A = I[0], I[1], I[2], I[3], I[4]
    ophi, ogam, _, _, ophit, _, _, _, ocs, _ = _layout(I)
    oR = H_R
    for x in range(m * n):
        W[_u(x)] = 0.0
    for k in range(K):
        j, i, r = I[_u(H_I + k)], I[_u(H_I + K + k)], I[_u(H_I + 2 * K + k)]
        refI = R[_u(oR + 6 * K + k)]
        # u = A s' (eq. 10) of each point, its body's position, velocity and angular velocity
        wj, ujx, ujy, zjx, zjy, zdjx, zdjy = _body_point(y, n, nb, j, R[_u(oR + k)], R[_u(oR + K + k)],
                                                         W[_u(ocs + 2 * j)], W[_u(ocs + 2 * j + 1)])
        wi, uix, uiy, zix, ziy, zdix, zdiy = _body_point(y, n, nb, i, R[_u(oR + 2 * K + k)], R[_u(oR + 3 * K + k)],
                                                         W[_u(ocs + 2 * i)], W[_u(ocs + 2 * i + 1)])
        dx = (zjx - zix) + (ujx - uix)                     # d = r_J^P - r_I^P
        dy = (zjy - ziy) + (ujy - uiy)
        wujx, wujy = wj * ujx, wj * ujy
        wuix, wuiy = wi * uix, wi * uiy
        dcx = wj * wujx - wi * wuix                        # -(relative centripetal acceleration)
        dcy = wj * wujy - wi * wuiy
        # n = A_ref n'; cn = conj(n)
        npx, npy = R[_u(oR + 4 * K + k)], R[_u(oR + 5 * K + k)]
        if r < nb and refI != 0.0:
            cr, sr = W[_u(ocs + 2 * r)], W[_u(ocs + 2 * r + 1)]
            nx, ny = cr * npx - sr * npy, sr * npx + cr * npy
            wr = y[_u(n + 3 * r + 2)]
        else:
            nx, ny = npx, npy
            wr = 0.0
        cnx, cny = nx, -ny
        p = cnx * dx - cny * dy                            # Re(conj(n) d), eq. (3)
        W[_u(ophi + k)] = p
        if wr != 0.0 or refI != 0.0:
            ddx = (zdjx - zdix) - (wujy - wuiy)            # relative point velocity
            ddy = (zdjy - zdiy) + (wujx - wuix)
            ax = dcx - 2.0 * wr * ddy                      # dcen + 2 i wr dd
            ay = dcy + 2.0 * wr * ddx
            W[_u(ogam + k)] = wr * wr * p + (cnx * ax - cny * ay)   # eq. (5), n turning with body I
        else:
            W[_u(ogam + k)] = cnx * dcx - cny * dcy            # eq. (5), fixed n
        W[_u(ophit + k)] = 0.0
        # Phi_q = Re(conj(n) G): x -> 1, y -> i, theta -> i u (J), minus for I, plus the turning n
        o = k * n
        if j < nb:
            W[_u(o + 3 * j)] += cnx
            W[_u(o + 3 * j + 1)] += -cny
            W[_u(o + 3 * j + 2)] += -(cnx * ujy + cny * ujx)   # Re(cn * i uJ)
        if i < nb:
            W[_u(o + 3 * i)] += -cnx
            W[_u(o + 3 * i + 1)] += cny
            gx = uix + refI * dx
            gy = uiy + refI * dy
            W[_u(o + 3 * i + 2)] += cnx * gy + cny * gx        # Re(cn * (-i g))
    oc0 = oR + 7 * K
    for a in range(A):
        row = K + a
        j, i = I[_u(H_I + 3 * K + a)], I[_u(H_I + 3 * K + A + a)]
        thj = y[_u(3 * j + 2)] if j < nb else 0.0
        thi = y[_u(3 * i + 2)] if i < nb else 0.0
        om = R[_u(oc0 + A + a)]
        W[_u(ophi + row)] = thj - thi - (R[_u(oc0 + a)] + om * t)
        W[_u(ogam + row)] = 0.0
        W[_u(ophit + row)] = -om
        o = row * n
        if j < nb:
            W[_u(o + 3 * j + 2)] += 1.0
        if i < nb:
            W[_u(o + 3 * i + 2)] -= 1.0


@njit(**LEAF)
def _cholesky_solve(I, W, oS, ob):
    """Solve S x = b in place in b (S: the lower triangle of W[oS:oS + m m], row-major, symmetric positive
    semidefinite, overwritten by its factor L; b = W[ob:ob + m]), visiting only the entries of L's pattern
    (``_structure``): the operations of the dense Cholesky that involve a non-zero, in its order.

    A pivot below 1e-12 of the largest diagonal entry (a redundant constraint) is dropped: that
    unknown is set to 0, which solves a consistent redundant system (a basic, not the minimum-norm,
    solution; the accelerations M^-1 (Q - Phi_q^T lam) are the same). Returns the number of
    dropped pivots."""
    m = I[2]
    d = I[5]                                              # the directory (``pack``)
    lrp, lrc, lcp, lcr = I[_u(d + 8)], I[_u(d + 9)], I[_u(d + 10)], I[_u(d + 11)]
    cmp, cmk = I[_u(d + 12)], I[_u(d + 13)]
    big = 0.0
    for j in range(m):
        big = max(big, abs(W[_u(oS + j * m + j)]))
    tol = 1e-12 * big
    dropped = 0
    q = cmp                                               # the common entries' pointers, column by column
    for j in range(m):
        rj = oS + j * m
        d = W[_u(rj + j)]
        for p in range(I[_u(lrp + j)], I[_u(lrp + j + 1)]):
            k = I[_u(lrc + p)]
            d -= W[_u(rj + k)] * W[_u(rj + k)]
        if not d > tol:
            dropped += 1
            W[_u(rj + j)] = 0.0
            for p in range(I[_u(lcp + j)], I[_u(lcp + j + 1)]):
                W[_u(oS + I[_u(lcr + p)] * m + j)] = 0.0
            q += I[_u(lcp + j + 1)] - I[_u(lcp + j)]
            continue
        d = math.sqrt(d)
        W[_u(rj + j)] = d
        for p in range(I[_u(lcp + j)], I[_u(lcp + j + 1)]):
            ri = oS + I[_u(lcr + p)] * m
            s = W[_u(ri + j)]
            for c in range(I[_u(q)], I[_u(q + 1)]):
                k = I[_u(cmk + c)]
                s -= W[_u(ri + k)] * W[_u(rj + k)]
            q += 1
            W[_u(ri + j)] = s / d
    for i in range(m):
        ri = oS + i * m
        if W[_u(ri + i)] == 0.0:
            W[_u(ob + i)] = 0.0
            continue
        s = W[_u(ob + i)]
        for p in range(I[_u(lrp + i)], I[_u(lrp + i + 1)]):
            k = I[_u(lrc + p)]
            s -= W[_u(ri + k)] * W[_u(ob + k)]
        W[_u(ob + i)] = s / W[_u(ri + i)]
    for i in range(m - 1, -1, -1):
        if W[_u(oS + i * m + i)] == 0.0:
            W[_u(ob + i)] = 0.0
            continue
        s = W[_u(ob + i)]
        for p in range(I[_u(lcp + i)], I[_u(lcp + i + 1)]):
            k = I[_u(lcr + p)]
            s -= W[_u(oS + k * m + i)] * W[_u(ob + k)]
        W[_u(ob + i)] = s / W[_u(oS + i * m + i)]
    return dropped


@njit(**LEAF)
def _solve(y, I, R, W, dy):
    """Eq. (9) with Baumgarte's gamma* for the kinematics and Q in W: qdd into dy[n:] and lambda (internal
    order) in W. (Phi_q M^-1 Phi_q^T) lam = Phi_q M^-1 Q - gamma*, qdd = M^-1 (Q - Phi_q^T lam)."""
    n, m, K, A = I[1], I[2], I[3], I[4]
    ophi, ogam, orhs, olam, ophit, oS, oQ, otmp, _, _ = _layout(I)
    d = I[5]                                               # the directory (``pack``)
    orp, orc, ocp, ocr = I[_u(d)], I[_u(d + 1)], I[_u(d + 2)], I[_u(d + 3)]
    osr, osc, osp, ost = I[_u(d + 4)], I[_u(d + 5)], I[_u(d + 6)], I[_u(d + 7)]
    om = H_R + 7 * K + 2 * A                               # 1/M in R
    a2, b2 = R[0], R[1]
    for i in range(n):
        W[_u(otmp + i)] = R[_u(om + i)] * W[_u(oQ + i)]
    for r in range(m):                                     # Phi_q M^-1 Q - gamma*
        s = 0.0
        pd = 0.0
        o = r * n
        for p in range(I[_u(orp + r)], I[_u(orp + r + 1)]):
            c = I[_u(orc + p)]
            s += W[_u(o + c)] * W[_u(otmp + c)]
            pd += W[_u(o + c)] * y[_u(n + c)]
        W[_u(orhs + r)] = s - W[_u(ogam + r)] + a2 * (pd + W[_u(ophit + r)]) + b2 * W[_u(ophi + r)]
        W[_u(olam + r)] = W[_u(orhs + r)]
    for e in range(I[_u(d + 14)]):                                 # S = Phi_q M^-1 Phi_q^T, its pattern's lower triangle
        o, oc = I[_u(osr + e)] * n, I[_u(osc + e)] * n
        v = 0.0
        for p in range(I[_u(osp + e)], I[_u(osp + e + 1)]):
            i = I[_u(ost + p)]
            v += W[_u(o + i)] * R[_u(om + i)] * W[_u(oc + i)]
        W[_u(oS + I[_u(osr + e)] * m + I[_u(osc + e)])] = v
    if m > 0:
        _cholesky_solve(I, W, oS, olam)                    # redundant rows dropped (see there)
    for i in range(n):                                     # M^-1 (Q - Phi_q^T lam)
        v = W[_u(otmp + i)]
        for p in range(I[_u(ocp + i)], I[_u(ocp + i + 1)]):
            r = I[_u(ocr + p)]
            v -= R[_u(om + i)] * W[_u(r * n + i)] * W[_u(olam + r)]
        dy[_u(n + i)] = v


@njit(**KERNEL)
def accelerations(q, qd, t, Q, I, R, W, qdd):
    """Kinematics and eq. (9) for the state (q, qd, t) and applied forces Q: qdd written, lambda in W."""
    n = I[1]
    y = np.concatenate((q, qd))
    dy = np.empty(2 * n)
    oQ = _layout(I)[6]
    for i in range(n):
        W[oQ + i] = Q[i]
    _rotations(y, I, W)
    _kinematics(y, t, I, R, W)
    _solve(y, I, R, W, dy)
    for i in range(n):
        qdd[i] = dy[n + i]


@internal(LEAF)
def _in_model_order(I, W, offset, out):
    """The constraint rows of W from ``offset`` (kernel row order) into ``out`` in model order."""
    otm = H_I + 3 * I[3] + 2 * I[4]
    for k in range(I[2]):
        out[k] = W[offset + I[otm + k]]


@njit(**KERNEL, inline="always")
def multipliers(I, W, lam_model):
    """Lambda of the last solve, in model order."""
    _in_model_order(I, W, _layout(I)[3], lam_model)


@njit(**LEAF)
def constraints(I, W, phi_model):
    """Phi of the last kinematics evaluation, in model order."""
    _in_model_order(I, W, _layout(I)[0], phi_model)


@njit(**LEAF)
def max_violation(I, W):
    """max |Phi| of the last kinematics evaluation [m or rad]."""
    ophi = _layout(I)[0]
    v = 0.0
    for k in range(I[2]):
        a = abs(W[_u(ophi + k)])
        if a > v:                                          # noqa: PLR1730 (a NaN is skipped, as before)
            v = a
    return v


# ---------------------------------------------------------------------------------- force joint
@internal(LEAF)
def _point(y, n, nb, b, sx, sy, W, ocs):
    """(x, y, xd, yd) of a point s' on body b (eq. 10-12) with the body's cos, sin in W; ground: (s', 0)."""
    w, ux, uy, x, yy, xd, yd = _body_point(y, n, nb, b, sx, sy, W[_u(ocs + 2 * b)], W[_u(ocs + 2 * b + 1)])
    return x + ux, yy + uy, xd - w * uy, yd + w * ux


@njit(**LEAF)
def _link_inputs(y, I, L, LR, W, u):
    """The bearing's inputs (e_x, e_y, v_x, v_y, omega_inner, omega_outer) of y, eq. (10)-(12), into u;
    the rotations of y (``_rotations``) must be in W."""
    nb, n = I[0], I[1]
    ocs = _layout(I)[8]
    hb, jb = L[1], L[2]
    xi, yi, vxi, vyi = _point(y, n, nb, hb, LR[0], LR[1], W, ocs)
    xj, yj, vxj, vyj = _point(y, n, nb, jb, LR[2], LR[3], W, ocs)
    u[0] = xj - xi
    u[1] = yj - yi
    u[2] = vxj - vxi
    u[3] = vyj - vyi
    u[4] = y[_u(n + 3 * jb + 2)] if jb < nb else 0.0
    u[5] = y[_u(n + 3 * hb + 2)] if hb < nb else 0.0


@internal(LEAF)
def _add_point_force(W, oQ, y, nb, b, fx, fy, ax, ay):
    """Generalized force of F = (fx, fy) applied at (ax, ay) on body b into Q = W[oQ:] (eq. 20-23)."""
    if b >= nb:
        return
    i = 3 * b
    W[_u(oQ + i)] += fx
    W[_u(oQ + i + 1)] += fy
    W[_u(oQ + i + 2)] += (ax - y[_u(i)]) * fy - (ay - y[_u(i + 1)]) * fx


@internal(LEAF)
def _add_link_force(y, I, L, LR, W, ex, ey, fx, fy):
    """Generalized forces of F on the housing body and -F on the journal body into Q in W, eq. (20)-(23);
    the rotations of y (``_rotations``) must be in W."""
    nb, n = I[0], I[1]
    oQ, _, ocs = _layout(I)[6:9]
    hb, jb = L[1], L[2]
    xi, yi, _, _ = _point(y, n, nb, hb, LR[0], LR[1], W, ocs)
    xj, yj, _, _ = _point(y, n, nb, jb, LR[2], LR[3], W, ocs)
    if L[3] == 1:                                         # eq. (14)-(15): at the contact points
        e = math.hypot(ex, ey)
        if e > 0.0:
            nx, ny = ex / e, ey / e
            _add_point_force(W, oQ, y, nb, hb, fx, fy, xi + LR[4] * nx, yi + LR[4] * ny)
            _add_point_force(W, oQ, y, nb, jb, -fx, -fy, xj + LR[5] * nx, yj + LR[5] * ny)
            return
    _add_point_force(W, oQ, y, nb, hb, fx, fy, xi, yi)    # at the ring centres
    _add_point_force(W, oQ, y, nb, jb, -fx, -fy, xj, yj)


@njit(**KERNEL, inline="always")
def force_of_model(fm, tau, ex, ey, vx, vy):
    """F(tau, e, v) = F0 + a1 s + a2 s^2 + K (e - e0) + C (v - v0) (``ForceModel``)."""
    s = tau - fm[0]
    dx, dy, dvx, dvy = ex - fm[7], ey - fm[8], vx - fm[9], vy - fm[10]
    return (fm[1] + s * (fm[3] + s * fm[5]) + fm[11] * dx + fm[12] * dy + fm[14] * dvx + fm[15] * dvy,
            fm[2] + s * (fm[4] + s * fm[6]) + fm[12] * dx + fm[13] * dy + fm[15] * dvx + fm[16] * dvy)


# ---------------------------------------------------------------------------------- the step
@njit(**KERNEL, inline="always")
def _applied(I, R, W):
    """Q^A of gravity [N, N, N m] into Q in W."""
    n, K, A = I[1], I[3], I[4]
    o = H_R + 7 * K + 2 * A + n
    oQ = _layout(I)[6]
    for i in range(n):
        W[_u(oQ + i)] = R[_u(o + i)]


@njit(**KERNEL, inline="always")
def rhs(tau, y, fm, I, R, L, LR, W, u, dy):
    """dy/dt = [qd, qdd] with the force joint's force given by the force model fm: ``stage_inputs``, the force
    at those inputs, ``stage_derivative``."""
    stage_inputs(y, I, R, L, LR, W, u)
    fx = fy = 0.0
    if L[0] == 1:
        fx, fy = force_of_model(fm, tau, u[0], u[1], u[2], u[3])
    stage_derivative(tau, y, fx, fy, I, R, L, LR, W, u, dy)


@njit(**KERNEL, inline="always")
def stage_inputs(y, I, R, L, LR, W, u):
    """The first half of ``rhs`` (and of ``mechanism.cosim.law_model_kernel``'s stages, whose force the caller
    gives): the rotations and Q^A of y into W and its bearing inputs into u (eq. 10-12)."""
    _rotations(y, I, W)
    _applied(I, R, W)
    if L[0] == 1:
        _link_inputs(y, I, L, LR, W, u)


@njit(**KERNEL, inline="always")
def stage_derivative(tau, y, fx, fy, I, R, L, LR, W, u, dy):
    """The second half of ``rhs`` after ``stage_inputs``: dy/dt = [qd, qdd] with the force joint's force (fx, fy)
    at the inputs u (eq. 20-23)."""
    n = I[1]
    if L[0] == 1:
        _add_link_force(y, I, L, LR, W, u[0], u[1], fx, fy)
    for i in range(n):
        dy[_u(i)] = y[_u(n + i)]
    _kinematics(y, tau, I, R, W)
    _solve(y, I, R, W, dy)


@njit(**KERNEL, inline="always")
def powers(y, I, R, W):
    """The powers [W] at the state y whose right-hand side was just evaluated (kinematics, lambda and Q in W):
    of the drivers lambda . Phi_t (the rheonomic constraints' work, e.g. the crank's M omega), of the applied
    forces Q^A . q' and of the force joint Q_link . q' (Q minus Q^A: the bearing force's work on the mechanism).
    With the velocity constraints met, dT/dt is their sum (eq. 4, 7, 9); the energy account integrates them
    with the RK4 stages (``advance``)."""
    n, m, K, A = I[1], I[2], I[3], I[4]
    _, _, _, olam, ophit, _, oQ, _, _, _ = _layout(I)
    drive = 0.0
    for r in range(m):
        drive += W[_u(olam + r)] * W[_u(ophit + r)]
    o = H_R + 7 * K + 2 * A + n
    app = 0.0
    total = 0.0
    for i in range(n):
        app += R[_u(o + i)] * y[_u(n + i)]
        total += W[_u(oQ + i)] * y[_u(n + i)]
    return drive, app, total - app


@njit(**KERNEL, inline="always")
def _stage_row(stages, row, y, u, nb, L):
    """The energy account's record of a stage state: its bearing inputs u and the ring angles (journal, housing)."""
    q = _u(row)
    for i in range(6):
        stages[q, i] = u[i]
    stages[q, 6] = y[3 * L[2] + 2] if L[2] < nb else 0.0
    stages[q, 7] = y[3 * L[1] + 2] if L[1] < nb else 0.0


@njit(**LEAF)
def advance(y, t0, hs, substeps, t_end, fm, k1, k1_valid, I, R, L, LR, W, u, acc=None, p1=None, stages=None):
    """``substeps`` RK4 steps of size hs from (t0, y) under the force model fm, on y in place (the caller passes a
    copy where it keeps the start); returns the end state's constraint violation max |Phi| (one kinematics
    evaluation per state) and whether it is finite. It allocates nothing (``LEAF``: no reference counting around
    its calls), and no wrapper copies y around it: each level of compiled calls re-optimises and re-emits the
    machine code of everything below it (docs/kernels.md, "Fifth pass").

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
    ork = _layout(I)[9]                  # in W: the four stages' dy/dt, the stage state, the stages' powers
    yt = W[ork + 4 * N:ork + 5 * N]
    opw = ork + 5 * N
    h2 = 0.5 * hs
    account = acc is not None and p1 is not None and stages is not None
    nb = I[0]
    for sub in range(substeps):
        t = t0 + sub * hs
        for st in range(4):                                # one rhs call site: inlined once
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
            if st == 0 and sub == 0 and k1_valid:
                for i in range(N):
                    k[_u(i)] = k1[_u(i)]
                if account:
                    W[_u(opw)], W[_u(opw + 1)], W[_u(opw + 2)] = p1[0], p1[1], p1[2]
                    if L[0] == 1:
                        _rotations(y, I, W)
                        _link_inputs(y, I, L, LR, W, u)
            else:                                          # ``rhs``, one call site of its parts: inlined once
                if st == 0 and sub > 0 and account and L[0] == 1:
                    _applied(I, R, W)                      # the rotations and inputs of y: the last substep's end
                else:
                    stage_inputs(yt, I, R, L, LR, W, u)
                fx = fy = 0.0
                if L[0] == 1:
                    fx, fy = force_of_model(fm, ts, u[0], u[1], u[2], u[3])
                stage_derivative(ts, yt, fx, fy, I, R, L, LR, W, u, k)
                if account:
                    o = opw + 3 * st
                    W[_u(o)], W[_u(o + 1)], W[_u(o + 2)] = powers(yt, I, R, W)
            if account:
                _stage_row(stages, 5 * sub + st, yt, u, nb, L)
        c = hs / 6.0
        for i in range(N):
            y[_u(i)] = y[_u(i)] + c * (W[_u(ork + i)] + 2.0 * (W[_u(ork + N + i)] + W[_u(ork + 2 * N + i)])
                                       + W[_u(ork + 3 * N + i)])
        if account:
            for j in range(3):
                acc[j] += c * (W[_u(opw + j)] + 2.0 * (W[_u(opw + 3 + j)] + W[_u(opw + 6 + j)]) + W[_u(opw + 9 + j)])
            if L[0] == 1:
                _rotations(y, I, W)
                _link_inputs(y, I, L, LR, W, u)
            _stage_row(stages, 5 * sub + 4, y, u, nb, L)
    finite = True
    for i in range(N):
        if not math.isfinite(y[i]):
            finite = False
            break
    if finite:
        if account and L[0] == 1 and substeps > 0:         # ``prepare`` but the rotations and inputs of y, there
            _kinematics(y, t_end, I, R, W)                  # since the last substep's end
        else:
            prepare(y, t_end, I, R, L, LR, W, u)
        return max_violation(I, W), True
    return math.nan, False


@njit(**LEAF)
def prepare(y, t, I, R, L, LR, W, u):
    """Kinematics of the state y at t into W and its bearing inputs into u (the tail of ``advance``)."""
    _rotations(y, I, W)
    _kinematics(y, t, I, R, W)
    if L[0] == 1:
        _link_inputs(y, I, L, LR, W, u)


@njit(**LEAF)
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
    _applied(I, R, W)
    if L[0] == 1:
        _rotations(y, I, W)
        _add_link_force(y, I, L, LR, W, ex, ey, fx, fy)
    for i in range(n):
        dy[i] = y[n + i]
    _solve(y, I, R, W, dy)
    multipliers(I, W, lam)
    if p1 is not None:
        p1[0], p1[1], p1[2] = powers(y, I, R, W)
    if row.shape[0] > 0 and L[0] == 0 and react.shape[0] == 4:
        otm = H_I + 3 * I[3] + 2 * I[4]
        fx = fy = 0.0
        for r in range(react[0], react[1]):
            k = I[otm + r]
            fx -= W[k * n + react[2]] * lam[r]
            fy -= W[k * n + react[3]] * lam[r]
    if row.shape[0] > 0:
        fill_row(row, probes, scale, y, dy, lam, u, fx, fy, t, cv, kinetic_energy(y, I, R), n)


@njit(**KERNEL, inline="always")
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


@njit(**KERNEL, inline="always")
def kinetic_energy(y, I, R):
    """T = qd^T M qd / 2 [J] of the state y = [q, qd]."""
    n, K, A = I[1], I[3], I[4]
    o = H_R + 7 * K + 2 * A + 2 * n
    T = 0.0
    for i in range(n):
        T += R[_u(o + i)] * (y[_u(n + i)] * y[_u(n + i)])
    return 0.5 * T
