"""``CompiledSystem``: the NumPy ``System``'s per-state API on the numba kernels (``kernels.py``).

It packs a ``System`` (which stays the reference and keeps assembly, reactions and the rest) into
the kernels' arrays once and evaluates Phi, gamma and eq. (9) through them. The master drives the
kernels directly (``mechanism.cosim.master``); this class is their Python face for tests and tools.
"""
from __future__ import annotations

import numpy as np

from mechanism.multibody import kernels as kn
from mechanism.multibody.solver import System


class CompiledSystem:
    """The compiled counterpart of ``system`` (same model, same Baumgarte parameters)."""

    def __init__(self, system: System):
        self.system = system
        self.n, self.m = system.n, system.m
        self.ints, self.reals = kn.pack(system)
        self.work = np.zeros(kn.workspace_size(self.ints))

    def accelerations(self, q: np.ndarray, qd: np.ndarray, t: float, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(qdd, lambda [model order]) of eq. (9) with Baumgarte stabilisation, as ``System.accelerations``."""
        qdd = np.empty(self.n)
        kn.accelerations(np.ascontiguousarray(q, float), np.ascontiguousarray(qd, float), float(t),
                         np.ascontiguousarray(Q, float), self.ints, self.reals, self.work, qdd)
        lam = np.empty(self.m)
        kn.multipliers(self.ints, self.work, lam)
        return qdd, lam

    def phi(self, q: np.ndarray, t: float) -> np.ndarray:
        """Constraint violations Phi(q, t) (eq. 3), model order."""
        self.accelerations(q, np.zeros(self.n), t, np.zeros(self.n))
        phi = np.empty(self.m)
        kn.constraints(self.ints, self.work, phi)
        return phi
