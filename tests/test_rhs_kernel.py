"""The sparse right-hand side of the multibody kernels (``kernels.rhs``, ``_solve``, ``_cholesky_solve``):
the structure ``pack`` derives from the model against the numbers of the NumPy ``System``, and the kernels'
results against the reference on random states with the energy account's path through ``advance``."""
from __future__ import annotations

import numpy as np
import pytest

from mechanism.cosim.coupling.base import ForceModel
from mechanism.cosim.joint import BearingLink
from mechanism.multibody import kernels as kn
from mechanism.multibody.model import Model, Revolute
from mechanism.multibody.solver import System
from mechanism.systems import double_pendulum
from tests.test_kernels import MODELS, _rel


def _redundant() -> tuple[System, np.ndarray, np.ndarray]:
    """The double pendulum with its pivot repeated (a rank-deficient Phi_q: dropped pivots)."""
    p = double_pendulum.DoublePendulumParameters()
    base = double_pendulum.build(p)
    pivot = base.joints[0]
    model = Model(bodies=base.bodies, joints=(*base.joints, Revolute("pivot_again", pivot.i, pivot.j)),
                  gravity=base.gravity)
    q, _ = double_pendulum.initial_state(System(base), p)
    qd = System(base).velocities(q, 0.0, np.array([0.0, 0.0, 1.0, 0.0, 0.0, -2.0]))
    return System(model), q, qd


CASES = {**{k: v[:3] for k, v in MODELS.items()}, "double-pendulum-redundant": _redundant()}


def _structure(system: System):
    """(Phi_q's pattern, S's lower entries, L's strictly lower entries) as ``pack`` lists them."""
    s = system
    st = kn._structure(s.n // 3, s.n, s._bJ, s._bI, s._aJ, s._aI)
    rows = [set(st[1][st[0][r]:st[0][r + 1]]) for r in range(s.m)]
    spattern = set(zip(st[4], st[5]))
    lpattern = {(i, k) for i in range(s.m) for k in st[9][st[8][i]:st[8][i + 1]]}
    return rows, spattern, lpattern


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_structure_holds_every_non_zero_of_the_numpy_system(name):
    """At random states, every non-zero of the reference Phi_q (internal row order), of S = Phi_q M^-1 Phi_q^T
    and of its Cholesky factor (NumPy, on S regularised where rows are redundant) is in the pattern the kernels
    visit: a structural zero the kernels skip is an exact zero of the dense evaluation."""
    system, q0, _ = CASES[name]
    rows, spattern, lpattern = _structure(system)
    rng = np.random.default_rng(2)
    for _ in range(10):
        q = q0 + rng.normal(0.0, 0.3, system.n)
        J = system.jacobian(q, 0.0)[system._from_model]          # internal order
        for r in range(system.m):
            assert set(np.flatnonzero(J[r])) <= rows[r]
        S = J @ np.diag(1.0 / system.mass) @ J.T
        assert {(r, c) for r, c in zip(*np.nonzero(np.tril(S)))} <= spattern
        L = np.linalg.cholesky(S + 1e-9 * np.trace(S) * np.eye(system.m))
        Lnz = {(r, c) for r, c in zip(*np.nonzero(np.tril(L, -1) * (np.abs(np.tril(L, -1)) > 1e-12 * np.abs(L).max())))}
        assert Lnz <= lpattern
        assert all((r, r) in spattern for r in range(system.m))


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_kernels_read_no_stale_workspace(name):
    """The kernels write every workspace entry they read: a workspace full of NaN gives the results of a zeroed
    one bit for bit (a pattern entry left from a previous call would show as a NaN or a difference)."""
    system, q0, qd0 = CASES[name]
    link = BearingLink(system, system.model.bearings[0]) if system.model.bearings else None
    ints, reals = kn.pack(system)
    L, LR = kn.pack_link(system, link.joint if link else None)
    fm = ForceModel(0.0, (30.0, -10.0), K=(1e6, 1e4, 1e6), C=(50.0, 0.0, 50.0)).coefficients
    rng = np.random.default_rng(4)
    n = system.n
    for _ in range(5):
        y = np.concatenate((q0 + rng.normal(0.0, 1e-3, n), qd0 + rng.normal(0.0, 1.0, n)))
        out = []
        for fill in (0.0, np.nan):
            W, u, dy = np.full(kn.workspace_size(ints), fill), np.zeros(6), np.zeros(2 * n)
            kn.rhs(0.01, y, fm, ints, reals, L, LR, W, u, dy)
            acc, p1, stages = np.zeros(3), np.zeros(3), np.zeros((10, 8))
            y2 = y.copy()
            cv, finite = kn.advance(y2, 0.0, 1e-5, 2, 2e-5, fm, dy, True, ints, reals, L, LR, W, u, acc, p1, stages)
            lam = np.zeros(system.m)
            kn.finish(y2, u[0], u[1], 3.0, -4.0, ints, reals, L, LR, W, u, dy, lam, np.zeros(0),
                      np.zeros((0, 3), np.int64), np.zeros(0), 2e-5, cv, np.zeros(0, np.int64), p1)
            out.append(np.concatenate((dy, y2, [cv, float(finite)], acc, p1, stages.ravel(), lam, u)))
        assert np.all(np.isfinite(out[0]))
        assert np.array_equal(out[0], out[1])


@pytest.mark.parametrize("name", sorted(CASES))
def test_rhs_matches_numpy_on_random_states(name):
    """``kernels.rhs`` (force joint with a linear force model where the model has one) against the NumPy
    System's eq. (9) on states off the constraint manifold: 1e-12 relative (1e-10 with redundant rows)."""
    system, q0, qd0 = CASES[name]
    link = BearingLink(system, system.model.bearings[0]) if system.model.bearings else None
    ints, reals = kn.pack(system)
    L, LR = kn.pack_link(system, link.joint if link else None)
    fm = ForceModel(0.0, (30.0, -10.0), K=(1e6, 1e4, 1e6), C=(50.0, 0.0, 50.0))
    W, u = np.zeros(kn.workspace_size(ints)), np.zeros(6)
    rng = np.random.default_rng(9)
    n = system.n
    tol = 1e-10 if name.endswith("redundant") else 1e-12
    for _ in range(25):
        q, qd = q0 + rng.normal(0.0, 1e-2, n), qd0 + rng.normal(0.0, 1.0, n)
        tau = rng.uniform(0.0, 0.1)
        Q = system.applied_forces(q, qd, tau)
        if link is not None:
            e = link.inputs(q, qd)
            link.generalized_force(q, e[0], e[1], *fm(tau, *e[:4]), Q)
        ref = np.concatenate((qd, system.accelerations(q, qd, tau, Q)[0]))
        dy = np.empty(2 * n)
        kn.rhs(tau, np.concatenate((q, qd)), fm.coefficients, ints, reals, L, LR, W, u, dy)
        assert _rel(dy, ref) <= tol
