"""The Python loop's ``law-model`` step with the compiled mechanism: a reference for the compiled loop bit for bit.

``law-model`` has no ``ForceModel`` (``LawModel.force_model`` returns None), so the Python loop integrates its step
with the master's NumPy right-hand side (``CouplingLoop.rhs``, ``_advance_with_energy``) and ``LawModel.force``,
where the compiled loop uses ``kernels``' mechanism (the same equations, other rounding: the two agree to the
rounding's growth, about 1e-10 of the eccentricity over 0.2 revolution at 1e-4 s). ``kernel_mechanism`` patches the
Python loop's two RK4 right-hand sides to the kernels' mechanism (``kernels.stage_inputs``, ``stage_derivative``,
``powers``: the compiled loop's arithmetic) around the same Python ``LawModel.force``: the coupling scheme stays the
Python reference and the compiled loop must then give its numbers bit for bit.
"""
from __future__ import annotations

import numpy as np

from mechanism.cosim import master
from mechanism.multibody import kernels as kn


def _stage(loop, tau, y, row=None):
    """dy/dt at (tau, y) with ``LawModel.force`` through the kernels' mechanism; with ``row`` also its powers
    and the stage's record (``kernels._stage_row``) in the loop's ``_stages``."""
    dy = np.empty(y.shape[0])
    u = loop._u
    kn.stage_inputs(y, loop._I, loop._R, loop._L, loop._LR, loop._W, u)
    fx, fy = loop.scheme.force(tau, u[0], u[1], u[2], u[3])
    kn.stage_derivative(tau, y, fx, fy, loop._I, loop._R, loop._L, loop._LR, loop._W, u, dy)
    if row is None:
        return dy
    powers = np.array(kn.powers(y, loop._I, loop._R, loop._W))
    kn._stage_row(loop._stages, row, y, u, loop._I[0], loop._L)
    return dy, powers


def _advance_with_energy(self, y, t0, hs, m, finish=True):
    """``CouplingLoop._advance_with_energy`` with the kernels' mechanism (``integrators.rk4_step``'s arithmetic)."""
    acc = np.zeros(3)
    h2 = 0.5 * hs
    for k in range(m):
        t, row = t0 + k * hs, 5 * k
        k1, p1 = _stage(self, t, y, row)
        k2, p2 = _stage(self, t + h2, y + h2 * k1, row + 1)
        k3, p3 = _stage(self, t + h2, y + h2 * k2, row + 2)
        k4, p4 = _stage(self, t + hs, y + hs * k3, row + 3)
        c = hs / 6.0
        y = y + c * (k1 + 2.0 * (k2 + k3) + k4)
        acc = acc + c * (p1 + 2.0 * (p2 + p3) + p4)
        kn._rotations(y, self._I, self._W)
        kn._link_inputs(y, self._I, self._L, self._LR, self._W, self._u)
        kn._stage_row(self._stages, row + 4, y, self._u, self._I[0], self._L)
    self._acc[:] = acc
    if np.all(np.isfinite(y)):
        self._energy_step(m, hs, finish)
    return y


def kernel_mechanism(monkeypatch) -> None:
    """Patch the Python loop (``CouplingLoop``) to integrate a step without a force model with the kernels'
    mechanism around the scheme's Python ``force`` (see the module docstring)."""
    start = master.CouplingLoop.start

    def patched_start(self, y):
        start(self, y)
        self.rhs = lambda tau, yy: _stage(self, tau, yy)

    monkeypatch.setattr(master.CouplingLoop, "start", patched_start)
    monkeypatch.setattr(master.CouplingLoop, "_advance_with_energy", _advance_with_energy)
