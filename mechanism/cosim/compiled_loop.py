"""The whole fixed-step communication step compiled (numba): a chunk of steps of ``run_master`` in one call.

A second implementation of what ``master.run_master`` + ``CouplingLoop.communicate`` do per step for the
interface-Jacobian schemes ``jacobian``, ``jacobian-drift``, ``jacobian-secant`` and ``jacobian-implicit`` and the
force-held schemes ``zoh``, ``extrap1``, ``extrap2`` and ``zoh-jacobi`` (``mechanism.cosim.coupling``), with the
in-process component (``component_kernel.law_exchange``) or an FMI 2.0 FMU called natively (``fmu_native``;
``component_call`` picks by ``kind``), held against that Python loop (the reference) by
tests/test_compiled_loop.py and tests/test_compiled_cosim.py, with the same order of operations:

* the scheme's force model (``InterfaceJacobianDrift.begin_step`` / ``InterfaceJacobianImplicit.begin_step``,
  ``ZeroOrderHold``, ``LinearExtrapolation``, ``QuadraticExtrapolation``: 17 coefficients of ``ForceModel``), the
  RK4 substeps of ``master.substeps`` (one for the force-held schemes); Jacobi ordering (``zoh-jacobi``): the
  component steps first, with the last inputs;
* a pass: ``kernels.advance`` (with the energy account's stages), the divergence checks, the secant ring
  speeds (``BearingLink.secant_ring_speeds``), the exchange, the push of the new ``Exchanged``;
* the iteration of ``jacobian-implicit``: rollback (the component's state saved once per step and restored
  per pass: a copy of ``cs``, or fmi2Get/SetFMUstate, freed at the end of the step and on every failure; the
  exchange history and the last inputs and force copied), the convergence test (``converged``), the contact-onset
  jumps (``onset_jumps``), the iterate-where-needed prediction (``next_pass_negligible``), ``max_iterations``;
* the accepted pass's energy integrals (``energy_kernel.stage_integrals``), the end-of-step evaluation
  (``kernels.finish``: the sample and the next step's first RK4 stage), and the sample row: the probes,
  the component's samples (cage angle, loaded balls, max ball load, ball loads), the energy account's
  columns (``EnergyAccount.update`` with the integrals), the ring speeds sent.

The exchange history is an array ``past`` (3 x 13, the fields of ``Exchanged`` in order) with its count (at most
the scheme's ``history``). ``run_steps``' arguments ``P`` (the in-process law) and ``LM`` (law-model's state) are
None for an FMU and for the other schemes: numba prunes the branches on them before typing, so each run compiles
(and loads) only its own component's and scheme's functions.
The driver (``mechanism.cosim.compiled_driver``) packs the Python objects into arrays and back.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from fmu_bearing.parameters import DAMPING_CONSTANT
from mechanism.cosim import component_call as cc
from mechanism.cosim import fmu_native
from mechanism.cosim import law_model_kernel as lmk
from mechanism.cosim.energy_kernel import stage_integrals
from mechanism.cosim.law_kernel import (
    HEADER,
    edge_tolerance,
    elastic_energy,
    sym_eig_max,
)
from mechanism.multibody.kernels import (
    KERNEL,
    advance,
    finish,
    force_of_model,
    internal,
)

#: failure codes of ``run_steps`` (fail[0]); fail[1] = step, fail[2] = t, fail[3:] the values the message names
#: INPUTS: the in-process law rejected the inputs (fail[3:9]); COMPONENT: the FMU refused a call (fail[3] its
#: status, fail[4] the call: one of the CALLS)
OK, NOT_FINITE, CONSTRAINT, INPUTS, FORCE, COMPONENT = 0, 1, 2, 3, 4, 5
#: the FMU calls a COMPONENT failure names (fail[4])
DO_STEP, GET_STATE, SET_STATE, FREE_STATE, SAMPLE = 0, 1, 2, 3, 4
#: counters (``counts``): substeps max, substeps total, iterated steps, passes, max passes, not converged,
#: predicted, component calls, recorded rows, component states saved, component states freed
N_COUNTS = 11
#: float settings (``fset``): mobility, substep limit, max constraint violation, iteration tol, cv (in/out),
#: contact law: cage start, journal and housing angle at t = 0; energy: start energy, stage cage offset,
#: cage start, journal and housing angle at t = 0; eccentricity limit; law-model: ``resolution``, ``min_substeps``
N_FSET = 16
#: int settings (``iset``): max substeps, pass limit, predict, iterative, secant, energy, theta_j, theta_i,
#: contact law present, constraints (m), end evaluation valid (in/out), component kind (``component_call``),
#: drift history, entries of past (in/out), force model (``MODELS``), Jacobi ordering, the scheme's history,
#: the run's last step (always recorded, also off the output stride), the law-model scheme (its law: ``PC``; the
#: step itself goes by its argument ``LM``), its onset corrections on
N_ISET = 20
#: force models (iset[14]): the interface-Jacobian ones (``drift_model``, ``trial_model``), ``hold_model``'s
MODELS = {"jacobian": 0, "zoh": 1, "extrap1": 2, "extrap2": 3}


@njit(**KERNEL)
def _copy(dst, src, n):
    """dst[:n] = src[:n] for 1-D arrays, as a loop (a slice assignment compiles numba's broadcasting checks and
    their error paths: seconds of the first run's compile, docs/kernels.md)."""
    for i in range(n):
        dst[i] = src[i]


@internal(KERNEL)
def _copy_rows(dst, src, rows):
    """dst[:rows, :] = src[:rows, :] for 2-D arrays of the same width, as a loop (see ``_copy``)."""
    for i in range(rows):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


@njit(**KERNEL)
def substeps(h, x, mobility, limit, cap):
    """``master.substeps`` for the exchange x (13 fields of ``Exchanged``)."""
    k = max(sym_eig_max(x[7], x[8], x[9]), 0.0)
    c = max(sym_eig_max(x[10], x[11], x[12]), 0.0)
    rate = math.sqrt(k * mobility) + c * mobility
    x = h * rate / limit
    if not x < cap:     # numba's ceil of inf, nan or >= 2**63 is INT64_MIN: cap it first (Python gives cap)
        return cap
    return max(1, min(cap, math.ceil(x)))


@njit(**KERNEL, inline="always")
def _linear(x, e_x, e_y, v_x, v_y):
    """``coupling.jacobian._linear``: F_x + K (e - e_x) + C (v - v_x) about the exchange x."""
    dx, dy, dvx, dvy = e_x - x[1], e_y - x[2], v_x - x[3], v_y - x[4]
    return (x[5] + x[7] * dx + x[8] * dy + x[10] * dvx + x[11] * dvy,
            x[6] + x[8] * dx + x[9] * dy + x[11] * dvx + x[12] * dvy)


@internal(KERNEL)
def drift_model(past, npast, drift_history, fm):
    """The force model of ``jacobian-drift`` (pass 0 of ``jacobian-implicit``): ForceModel.linear(past[-1], d)
    with the previous step's drift d (``InterfaceJacobianDrift.begin_step``) into fm."""
    ax = ay = 0.0
    if drift_history and npast == 2:
        a, b = past[npast - 2], past[npast - 1]
        px, py = _linear(a, b[1], b[2], b[3], b[4])
        dt = b[0] - a[0]
        ax, ay = (b[5] - px) / dt, (b[6] - py) / dt
    x = past[npast - 1]
    fm[0], fm[1], fm[2], fm[3], fm[4], fm[5], fm[6] = x[0], x[5], x[6], ax, ay, 0.0, 0.0
    fm[7], fm[8], fm[9], fm[10] = x[1], x[2], x[3], x[4]
    for i in range(6):
        fm[11 + i] = x[7 + i]


@internal(KERNEL)
def hold_model(model, past, npast, fm):
    """The force models of the force-held schemes into fm: ``zoh`` (``ZeroOrderHold``: F_n held), ``extrap1``
    (``LinearExtrapolation``: F_n + (F_n - F_{n-1}) (tau - t_n) / (t_n - t_{n-1})), ``extrap2``
    (``QuadraticExtrapolation``: the Newton form through the last three forces), lower order until the history
    exists (``model``: their ``MODELS`` codes)."""
    for i in range(fm.shape[0]):
        fm[i] = 0.0
    c = past[npast - 1]
    fm[0], fm[1], fm[2] = c[0], c[5], c[6]
    if model == 2 or (model == 3 and npast == 2):
        if npast >= 2:
            b = past[npast - 2]
            dt = c[0] - b[0]
            fm[3], fm[4] = (c[5] - b[5]) / dt, (c[6] - b[6]) / dt
    elif model == 3 and npast == 3:
        a, b = past[0], past[1]
        cbx, cby = (c[5] - b[5]) / (c[0] - b[0]), (c[6] - b[6]) / (c[0] - b[0])
        bax, bay = (b[5] - a[5]) / (b[0] - a[0]), (b[6] - a[6]) / (b[0] - a[0])
        qx, qy = (cbx - bax) / (c[0] - a[0]), (cby - bay) / (c[0] - a[0])
        w = c[0] - b[0]
        fm[3], fm[4], fm[5], fm[6] = cbx + qx * w, cby + qy * w, qx, qy


@internal(KERNEL)
def trial_model(a, x, jumps, njumps, fm):
    """``InterfaceJacobianImplicit.begin_step`` with a trial: the mean tangent matrices, the step's own drift
    through both ends (start exchange a, the last pass's end x) and the onset jumps' quadratic terms, into fm."""
    m = np.zeros(13)    # zeros as everywhere here (np.empty would compile one more of numba's array makers)
    for i in range(7):
        m[i] = a[i]
    for i in range(6):
        m[7 + i] = 0.5 * (a[7 + i] + x[7 + i])
    px, py = _linear(m, x[1], x[2], x[3], x[4])
    dt = x[0] - a[0]
    ax, ay = (x[5] - px) / dt, (x[6] - py) / dt
    a2x = a2y = 0.0
    for j in range(njumps):
        g = 3.0 - 6.0 * jumps[j, 0]
        ax, ay = ax + g * jumps[j, 1] / dt, ay + g * jumps[j, 2] / dt
        a2x, a2y = a2x - g * jumps[j, 1] / (dt * dt), a2y - g * jumps[j, 2] / (dt * dt)
    fm[0], fm[1], fm[2], fm[3], fm[4], fm[5], fm[6] = m[0], m[5], m[6], ax, ay, a2x, a2y
    fm[7], fm[8], fm[9], fm[10] = m[1], m[2], m[3], m[4]
    for i in range(6):
        fm[11 + i] = m[7 + i]


@njit(**KERNEL)
def converged(a, b, tol, e_scale):
    """``InterfaceJacobianImplicit.converged``: two passes' end force and eccentricity agree to tol."""
    f_scale = max(1.0, abs(b[5]), abs(b[6]))
    return (abs(a[5] - b[5]) <= tol * f_scale and abs(a[6] - b[6]) <= tol * f_scale
            and abs(a[1] - b[1]) <= tol * e_scale and abs(a[2] - b[2]) <= tol * e_scale)


@njit(**KERNEL)
def onset_jumps(P, a, cage_a, b, cage_b, jumps):
    """``coupling.implicit.onset_jumps`` (law P of ``law_kernel.pack_bearing``) into the rows of ``jumps``
    (theta, J_x, J_y); returns their count. Constant damping only (eq. 18); the oil film has none."""
    if int(P[3]) != DAMPING_CONSTANT or P[4] == 0.0:
        return 0
    nb = int(P[0])
    C, half = P[4], P[2]
    count = 0
    # a ball clearly loaded, or clearly unloaded, at both ends has no jump: settled from e in the cage's frame at
    # both ends and the law's table of the balls' places (cos, sin of 2 pi r / nb), within |e| 1e-15 (8 + |angle|)
    # of the exact deflections below, far inside tol (as ``law_model_kernel.onset_corrections``)
    ca, sa, cb, sb = math.cos(cage_a), math.sin(cage_a), math.cos(cage_b), math.sin(cage_b)
    xa, ya = a[1] * ca + a[2] * sa, a[2] * ca - a[1] * sa
    xb, yb = b[1] * cb + b[2] * sb, b[2] * cb - b[1] * sb
    tol_a = edge_tolerance(half, a[1], a[2], cage_a)
    tol_b = edge_tolerance(half, b[1], b[2], cage_b)
    for r in range(nb):
        cr, sr = P[HEADER + r], P[HEADER + nb + r]
        ea, eb = xa * cr + ya * sr - half, xb * cr + yb * sr - half
        if (ea > tol_a and eb > tol_b) or (ea < -tol_a and eb < -tol_b):
            continue
        pa = cage_a + 2.0 * math.pi * r / nb                      # eq. (17)
        pb = cage_b + 2.0 * math.pi * r / nb
        da = a[1] * math.cos(pa) + a[2] * math.sin(pa) - half
        db = b[1] * math.cos(pb) + b[2] * math.sin(pb) - half
        if (da > 0.0) == (db > 0.0):
            continue
        theta = da / (da - db)
        phi = pa + theta * (pb - pa)
        ux, uy = math.cos(phi), math.sin(phi)
        vr = (a[3] + theta * (b[3] - a[3])) * ux + (a[4] + theta * (b[4] - a[4])) * uy
        jump = C * max(vr, 0.0) * (1.0 if da <= 0.0 else -1.0)
        if jump != 0.0:
            jumps[count, 0], jumps[count, 1], jumps[count, 2] = theta, jump * ux, jump * uy
            count += 1
    return count


@internal(KERNEL)
def same_jumps(a, na, b, nb, tol=1e-3):
    """``master._same_jumps``: the same onsets (count, positions, jumps) within tol."""
    if na != nb:
        return False
    for k in range(na):
        if not (abs(a[k, 0] - b[k, 0]) <= tol and math.hypot(a[k, 1] - b[k, 1], a[k, 2] - b[k, 2])
                <= tol * math.hypot(b[k, 1], b[k, 2])):
            return False
    return True


@internal(KERNEL)
def next_pass_negligible(fm, b, mobility, h, tol):
    """``CouplingLoop._next_pass_negligible`` for this pass's force model fm and its end exchange b."""
    if mobility <= 0.0:
        return False
    fx, fy = force_of_model(fm, b[0], b[1], b[2], b[3], b[4])
    return mismatch_negligible(b[5] - fx, b[6] - fy, b, mobility, h, tol)


@internal(KERNEL)
def mismatch_negligible(dx, dy, b, mobility, h, tol):
    """``CouplingLoop._next_pass_negligible`` from the end mismatch (dx, dy) [N] of this pass's force model."""
    d = math.hypot(dx, dy) * mobility
    de, dv = d * h * h / 6.0, d * h / 2.0
    k = max(sym_eig_max(b[7], b[8], b[9]), 0.0)
    c = max(sym_eig_max(b[10], b[11], b[12]), 0.0)
    return (k * de + c * dv <= tol * max(1.0, abs(b[5]), abs(b[6]))
            and de <= tol * max(1e-6, math.hypot(b[1], b[2])))


@internal(KERNEL)
def k1_valid(fm, t0, xin, xf):
    """``CouplingLoop._k1_valid`` once the stored end evaluation belongs to (y, t0)."""
    if fm[0] != t0 or fm[1] != xf[0] or fm[2] != xf[1]:
        return False
    if fm[7] == xin[0] and fm[8] == xin[1] and fm[9] == xin[2] and fm[10] == xin[3]:
        return True
    for i in range(11, 17):
        if fm[i] != 0.0:
            return False
    return True


@internal(KERNEL)
def _push(past, npast, x, history):
    """Append x to the exchange history (``history`` kept: the scheme's deque); returns the new count."""
    row = npast       # loops, not slice assignments (their shape-mismatch error path compiles for seconds: _copy)
    if npast == history:
        for k in range(history - 1):
            for j in range(past.shape[1]):
                past[k, j] = past[k + 1, j]
        row = history - 1
    for j in range(past.shape[1]):
        past[row, j] = x[j]
    return row + 1


@internal(KERNEL)
def _fail(fail, code, step, t, v0, v1, v2, v3, v4, v5):
    """Note a failure in ``fail`` (see OK .. COMPONENT). Callers pass every argument, the code as ``np.int64`` and
    the values as floats: one compiled specialisation (literal codes and omitted defaults made nine)."""
    fail[0], fail[1], fail[2] = code, step, t
    fail[3], fail[4], fail[5], fail[6], fail[7], fail[8] = v0, v1, v2, v3, v4, v5


@internal(KERNEL)
def _release(kind, H, state, counts) -> int:
    """Free the step's saved component state (``component_call.free``), counted."""
    status = cc.free(kind, H, state)
    counts[10] += 1
    return status


@njit(**KERNEL)
def _exchange(kind, P, ecc_limit, cs, H, vr_in, vr_out, t0, h, sent, out, step, t, fail, counts) -> bool:
    """The component's exchange (``component_call.exchange``), counted; False (``fail`` set) if refused.
    ``P`` None: an FMU, called straight through ``fmu_native`` (``component_call.exchange``'s FMU branch): numba
    prunes the other branch for a None argument, so the in-process law is not compiled into an FMU run's step."""
    if P is None:
        status = fmu_native.exchange(H, vr_in, sent, t0, h, vr_out, out)
    else:
        status = cc.exchange(kind, P, ecc_limit, cs, H, vr_in, vr_out, t0, h, sent, out)
    if status < 0 or status > 1:
        if P is not None:
            _fail(fail, np.int64(INPUTS), step, t, sent[0], sent[1], sent[2], sent[3], sent[4], sent[5])
        else:
            _fail(fail, np.int64(COMPONENT), step, t, float(status), float(DO_STEP), 0.0, 0.0, 0.0, 0.0)
        return False
    counts[7] += 1
    return True


@njit(**KERNEL)
def run_steps(y, first, last, h, every, I, R, L, LR, W, u, dy, lam, p1, acc, stages, probes, scale, react,
              data, cols, P, cs, H, vr_in, vr_out, vr_real, vr_int, vr_bool, PC, PE, past, xin, xf, integrals,
              counts, fset, iset, sent, fail, LM, FM):
    """Communication steps ``first`` .. ``last`` from the state y at t = (first - 1) h; returns the state
    reached (the last step's end, or the start of the step that failed: ``fail[0]`` != OK then).

    ``data``: the sample table (rows appended at counts[8], every ``every``-th step); ``cols``: columns of
    omega_inner, omega_outer, kinetic_energy, the 6 energy columns (-1: no account) and the component's samples.
    The component (``component_call``, kind iset[11]): in-process ``P``, its law, and ``cs``, its state
    (``component_kernel``); an FMU: the handle ``H`` and the value references of its inputs, coupling outputs and
    sampled reals, integers and booleans (``fmu_native.endpoint_references``). ``PC``: the contact law locating
    onsets (empty: none); ``PE``: the energy account's law. ``past`` (3 x 13) with iset[13] entries, ``xin`` and
    ``xf``: the history, last inputs and force of the loop (updated in place). ``sent``: the last inputs sent.

    Three arguments may be None, and numba then compiles a step without what they select (it prunes a branch on an
    argument that is None before typing it, but not one on an array: ``if LM is not None`` keeps both sides when LM
    is an array): ``P`` None for an FMU (no in-process law); for law-model, ``LM`` its state
    (``law_model_kernel.LM_SIZE``, zeroed here with its resolution fset[14]) and ``FM`` None; for the other
    schemes ``LM`` None and ``FM`` their force model's coefficients (17, ``kernels.force_of_model``; zeroed here).
    Every branch between the two is an ``if`` on the one that is None, so a run compiles, and a warm run loads,
    the step of its own component and scheme only (law-model's without the force models, ``kernels.advance`` and
    their helpers: the warm-up's loop stage 5.5 s instead of 7.9 s in two cold runs' timelines, docs/kernels.md).
    """
    mobility, sub_limit, max_cv, tol = fset[0], fset[1], fset[2], fset[3]
    max_sub, limit, predict, iterative, secant = iset[0], iset[1], iset[2] != 0, iset[3] != 0, iset[4] != 0
    energy, tj, ti, has_law, constrained = iset[5] != 0, iset[6], iset[7], iset[8] != 0, iset[9] != 0
    drift_history = iset[12] != 0
    kind = iset[11]
    model, jacobi, history = iset[14], iset[15] != 0, iset[16]
    nb_c = int(PC[0]) if PC.shape[0] > 0 else 0
    jumps = np.zeros((max(nb_c, 1), 3))
    onset_corr = iset[19] != 0    # law-model (law_model_kernel): its state LM (None: not law-model), work arrays
    if LM is not None:
        for i in range(LM.shape[0]):
            LM[i] = 0.0
        LM[18] = fset[14]
        LM[19] = fset[15]
    if FM is not None:
        for i in range(FM.shape[0]):
            FM[i] = 0.0
    lout = np.zeros(10)
    lloads = np.zeros(max(nb_c, 1))
    onsets = np.zeros((max(max_sub, 1), 5))
    bounds = np.zeros((max(max_sub, 1) + 1, 4))
    xs = np.zeros(13)
    trial_jumps = np.zeros((max(nb_c, 1), 3))
    x = np.zeros(13)
    start = np.zeros(13)
    prev = np.zeros(13)
    trial = np.zeros(13)
    snap_past = np.zeros((past.shape[0], past.shape[1]))
    snap_xin = np.zeros(6)
    snap_xf = np.zeros(2)
    snap_cs = np.zeros(cs.shape[0])
    no_row = np.zeros(0)
    out = np.zeros(cc.N_COUPLING)
    npast = iset[13]
    ns = cols.shape[0] - 9
    samples = np.zeros(ns)
    ecc_limit = fset[13]
    for step in range(first, last + 1):
        t0 = (step - 1) * h
        t = step * h
        _copy(start, past[npast - 1], start.shape[0])
        cage_start = 0.0
        if has_law:   # energy.kinematic_cage_angle
            cage_start = fset[5] + ((y[tj] - fset[6]) * PC[11] + (y[ti] - fset[7]) * PC[12])
        if LM is not None:
            lmk.set_cage(LM, PC, cage_start, xin[4], xin[5])
        snap_npast = npast
        state = 0
        if iterative:
            status, state = cc.save(kind, cs, snap_cs, H)
            if status < 0 or status > 1:
                _fail(fail, np.int64(COMPONENT), step, t, float(status), float(GET_STATE), 0.0, 0.0, 0.0, 0.0)
                return y
            counts[9] += 1
            _copy_rows(snap_past, past, past.shape[0])
            _copy(snap_xin, xin, xin.shape[0])
            _copy(snap_xf, xf, xf.shape[0])
        have_prev = False
        have_trial = False
        ntrial = np.int64(0)     # not the literal 0: a call's literal argument is a specialisation of its own
        passes = 0
        m = 1
        hs = h
        y_end = y
        for passes in range(1, (limit if iterative else 1) + 1):
            if jacobi:   # the component steps first, with the last inputs (master.CouplingLoop.advance)
                for i in range(6):
                    sent[i] = xin[i]
                if not _exchange(kind, P, ecc_limit, cs, H, vr_in, vr_out, t0, h, sent, out, step, t, fail,
                                 counts):
                    if iterative:    # no iterative Jacobi scheme today; free the step's state as every exit does
                        _release(kind, H, state, counts)
                    return y
            if LM is not None:   # LawModel.begin_step, substep_tangent, set_substeps
                lmk.begin(LM, PC, lout, lloads, past[npast - 1], trial, have_trial, h)
                lmk.substep_tangent(LM, past[npast - 1], xs)
                m = lmk.at_least(LM, substeps(h, xs, mobility, sub_limit, max_sub), max_sub)
                if onset_corr and have_trial and int(LM[17]) == m:
                    lmk.onset_corrections(LM, PC, m, bounds, trial, onsets)
                else:
                    for k in range(m):
                        onsets[k, 4] = 0.0
                LM[17] = m
            if FM is not None:   # the other schemes: their force model over the step
                if model != 0:
                    hold_model(model, past, npast, FM)
                elif have_trial:
                    trial_model(past[npast - 1], trial, trial_jumps, ntrial, FM)
                else:
                    drift_model(past, npast, drift_history, FM)
                m = substeps(h, past[npast - 1], mobility, sub_limit, max_sub) if model == 0 else 1
            counts[0] = max(counts[0], m)
            counts[1] += m
            hs = h / m
            # with the account's arrays also without an account (one specialisation to compile): the powers and
            # stages are computed and not used, the state and the inputs are the same
            for i in range(acc.shape[0]):
                acc[i] = 0.0
            if LM is not None:
                y_end = y.copy()
                drift, finite = lmk.advance(y_end, t0, hs, m, t, LM, PC, lout, lloads, onsets, bounds, I, R, L, LR, W,
                                            u, acc, stages)
            if FM is not None:
                k1v = iset[10] != 0 and k1_valid(FM, t0, xin, xf)
                y_end = y.copy()
                drift, finite = advance(y_end, t0, hs, m, t, FM, dy, k1v, I, R, L, LR, W, u, acc, p1, stages)
            if not finite:
                _fail(fail, np.int64(NOT_FINITE), step, t, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
                if iterative:
                    _release(kind, H, state, counts)
                return y
            if constrained:
                fset[4] = drift
                if drift > max_cv:
                    _fail(fail, np.int64(CONSTRAINT), step, t, drift, 0.0, 0.0, 0.0, 0.0, 0.0)
                    if iterative:
                        _release(kind, H, state, counts)
                    return y
            if not jacobi:
                for i in range(6):
                    sent[i] = u[i]
                if secant:   # BearingLink.secant_ring_speeds
                    sent[4] = (y_end[tj] - y[tj]) / h
                    sent[5] = (y_end[ti] - y[ti]) / h
                if not _exchange(kind, P, ecc_limit, cs, H, vr_in, vr_out, t0, h, sent, out, step, t, fail,
                                 counts):
                    if iterative:
                        _release(kind, H, state, counts)
                    return y
            s = 0.0
            for k in range(8):
                s += out[k]
            if not math.isfinite(s):
                _fail(fail, np.int64(FORCE), step, t, out[0], out[1], 0.0, 0.0, 0.0, 0.0)
                if iterative:
                    _release(kind, H, state, counts)
                return y
            x[0] = t
            for i in range(4):    # the inputs the force belongs to: u_{n+1}, or u_n with Jacobi ordering
                x[1 + i] = xin[i] if jacobi else u[i]
            for k in range(8):
                x[5 + k] = out[k]
            npast = _push(past, npast, x, history)
            iset[13] = npast
            for i in range(6):
                xin[i] = u[i]
            xf[0], xf[1] = out[0], out[1]
            if not iterative:
                break
            end = past[npast - 1]
            if have_prev and converged(prev, end, tol, max(1e-6, math.hypot(end[1], end[2]))):
                break
            if passes == limit:
                counts[5] += 1
                break
            nj = np.int64(0)
            if has_law:   # the onset jumps (law-model: its first pass is accepted only without one)
                cage_end = fset[5] + ((y_end[tj] - fset[6]) * PC[11] + (y_end[ti] - fset[7]) * PC[12])
                nj = onset_jumps(PC, start, cage_start, end, cage_end, jumps)
            if predict and ((nj == 0) if passes == 1 else same_jumps(jumps, nj, trial_jumps, ntrial)):
                if LM is not None:   # LawModel.end_mismatch: the first pass only, no onset to correct in its substeps
                    accept = passes == 1 and mobility > 0.0 and not lmk.any_onset(LM, PC, m, bounds, end, onsets)
                    if accept:
                        mx, my = lmk.end_mismatch(LM, PC, lout, lloads, end)
                        accept = mismatch_negligible(mx, my, end, mobility, h, tol)
                if FM is not None:
                    accept = next_pass_negligible(FM, end, mobility, h, tol)
                if accept:
                    counts[6] += 1
                    break
            _copy(prev, end, end.shape[0])
            have_prev = True
            _copy(trial, end, end.shape[0])
            _copy_rows(past, snap_past, past.shape[0])
            npast = snap_npast
            iset[13] = npast
            _copy(xin, snap_xin, xin.shape[0])
            _copy(xf, snap_xf, xf.shape[0])
            status = cc.restore(kind, cs, snap_cs, H, state)
            if status < 0 or status > 1:
                _fail(fail, np.int64(COMPONENT), step, t, float(status), float(SET_STATE), 0.0, 0.0, 0.0, 0.0)
                _release(kind, H, state, counts)
                return y
            _copy_rows(trial_jumps, jumps, nj)
            ntrial = nj
            have_trial = True
        if iterative:   # CouplingLoop.release
            status = _release(kind, H, state, counts)
            if status < 0 or status > 1:
                _fail(fail, np.int64(COMPONENT), step, t, float(status), float(FREE_STATE), 0.0, 0.0, 0.0, 0.0)
                return y
        if energy:   # the accepted pass's integrals (CouplingLoop._integrate_energy)
            d_, wc = stage_integrals(PE, stages, m, hs, fset[9])
            integrals[0] += d_
            integrals[1] += acc[0]
            integrals[2] += wc
            integrals[3] += acc[1]
            integrals[4] += acc[2]
        if iterative:
            counts[2] += 1
            counts[3] += passes
            counts[4] = max(counts[4], passes)
        y = y_end
        record = step % every == 0 or step == iset[17]
        row = data[counts[8]] if record else no_row
        finish(y, xin[0], xin[1], xf[0], xf[1], I, R, L, LR, W, u, dy, lam, row, probes, scale, t, fset[4], react, p1)
        iset[10] = 1
        if record:
            counts[8] += 1
            if ns > 0:   # the component's samples (the endpoint's sample / sample_into)
                status = cc.sample(kind, cs, H, vr_real, vr_int, vr_bool, samples)
                if status < 0 or status > 1:
                    _fail(fail, np.int64(COMPONENT), step, t, float(status), float(SAMPLE), 0.0, 0.0, 0.0, 0.0)
                    return y
                for k in range(ns):
                    row[cols[9 + k]] = samples[k]
            if energy:   # EnergyAccount.update with the integrals
                kinetic = row[cols[2]]
                cage = fset[10] + ((y[tj] - fset[11]) * PE[11] + (y[ti] - fset[12]) * PE[12])
                potential = elastic_energy(PE, u[0], u[1], cage)
                row[cols[3]] = potential
                row[cols[4]] = integrals[0]
                row[cols[5]] = integrals[1]
                row[cols[6]] = integrals[2]
                row[cols[7]] = integrals[3]
                row[cols[8]] = (kinetic + potential + integrals[0] - integrals[1] - integrals[3] - integrals[2]
                                - fset[8])
            if secant:
                row[cols[0]], row[cols[1]] = sent[4], sent[5]
    fail[0] = OK
    return y
