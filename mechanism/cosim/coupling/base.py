"""The coupling-scheme interface: what the master knows of the component (``Exchanged``) and ``Scheme``.

A scheme keeps the last exchanges and, within a communication step, returns the force model the
mechanism sees (``force``). New schemes subclass ``Scheme`` (one file per family, like SciPy's
``OdeSolver``) and are registered in ``mechanism.cosim.coupling.SCHEMES``.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class Exchanged:
    """What the master knows of the bearing at a communication point (SI)."""

    t: float
    e_x: float
    e_y: float
    v_x: float
    v_y: float
    F_x: float
    F_y: float
    k_xx: float = 0.0
    k_xy: float = 0.0
    k_yy: float = 0.0
    c_xx: float = 0.0
    c_xy: float = 0.0
    c_yy: float = 0.0


class Scheme:
    """Base: holds the last exchanges and returns the force model for the current step."""

    name = "base"
    ordering = "gauss-seidel"
    uses_tangent = False
    history = 1

    def __init__(self):
        self.past: deque[Exchanged] = deque(maxlen=self.history)
        self._t0 = 0.0
        self._h = 1.0

    def push(self, x: Exchanged) -> None:
        """Record the exchange at a communication point (the newest comes last)."""
        self.past.append(x)

    def begin_step(self, t: float, h: float) -> None:
        self._t0, self._h = t, h

    def force(self, tau: float, e_x: float, e_y: float, v_x: float, v_y: float) -> tuple[float, float]:
        raise NotImplementedError
