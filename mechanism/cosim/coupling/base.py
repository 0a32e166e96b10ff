"""The coupling-scheme interface: what the master knows of the component (``Exchanged``), ``Scheme``
and the per-step force model a scheme hands the master (``ForceModel``).

A scheme keeps the last exchanges and, within a communication step, returns the force the mechanism
sees. New schemes subclass ``Scheme`` (one file per family, like SciPy's ``OdeSolver``) and are
registered in ``mechanism.cosim.coupling.SCHEMES``.

Two ways to say the force, one meaning:

* ``force(tau, e_x, e_y, v_x, v_y)``: the force at one time and interface state (Python; the
  reference, and the only way for a scheme whose force is not of the form below);
* ``force_model(t0, h)``: called once per communication step after ``begin_step(t0, h)``, it returns
  the coefficients of that step's force as a ``ForceModel``

      F(tau, e, v) = F0 + a1 (tau - t_ref) + a2 (tau - t_ref)^2 + K (e - e0) + C (v - v0)

  (F0, a1, a2, e0, v0 2-vectors; K, C symmetric 2x2), which the compiled master step evaluates
  without calling back into Python. ``None`` (the default) means "not expressible": the master then
  integrates the step through ``force`` (slower, same result). A scheme that overrides
  ``force_model`` must give the same force as its ``force`` (tests/test_kernels.py holds every
  registered scheme to it).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np


def sym_eig_max(a: float, b: float, c: float) -> float:
    """Largest eigenvalue of the symmetric 2x2 matrix [[a, b], [b, c]] (a tangent K or C of ``Exchanged``: the
    stiffest direction; compiled as ``law_kernel.sym_eig_max``)."""
    return 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)


#: Layout of ``ForceModel.coefficients`` (float64, length 17), the array the compiled step reads.
FORCE_MODEL_FIELDS = ("t_ref", "F0_x", "F0_y", "a1_x", "a1_y", "a2_x", "a2_y", "e0_x", "e0_y", "v0_x", "v0_y",
                      "k_xx", "k_xy", "k_yy", "c_xx", "c_xy", "c_yy")


@dataclass(slots=True)
class Exchanged:
    """What the master knows of the bearing at a communication point (SI). Treat it as immutable; it is
    not ``frozen`` because the master builds one per communication step and a frozen dataclass's
    ``__init__`` costs several times more."""

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


class ForceModel:
    """One step's force F(tau, e, v) = F0 + a1 s + a2 s^2 + K (e - e0) + C (v - v0), s = tau - t_ref (SI).

    F [N], a1 [N/s], a2 [N/s^2], e0 [m], v0 [m/s], K = [[k_xx, k_xy], [k_xy, k_yy]] [N/m],
    C = [[c_xx, c_xy], [c_xy, c_yy]] [N s/m]. ``coefficients`` holds them in the order of
    ``FORCE_MODEL_FIELDS``.
    """

    __slots__ = ("coefficients",)

    def __init__(self, t_ref: float, F0: tuple[float, float], a1: tuple[float, float] = (0.0, 0.0),
                 a2: tuple[float, float] = (0.0, 0.0), e0: tuple[float, float] = (0.0, 0.0),
                 v0: tuple[float, float] = (0.0, 0.0), K: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 C: tuple[float, float, float] = (0.0, 0.0, 0.0)):
        self.coefficients = np.array((t_ref, *F0, *a1, *a2, *e0, *v0, *K, *C), dtype=np.float64)

    @classmethod
    def linear(cls, x: Exchanged, a1: tuple[float, float] = (0.0, 0.0)) -> "ForceModel":
        """F_n + a1 (tau - t_n) + K_n (e - e_n) + C_n (v - v_n) about the exchange x."""
        return cls(x.t, (x.F_x, x.F_y), a1, (0.0, 0.0), (x.e_x, x.e_y), (x.v_x, x.v_y),
                   (x.k_xx, x.k_xy, x.k_yy), (x.c_xx, x.c_xy, x.c_yy))

    def __call__(self, tau: float, e_x: float, e_y: float, v_x: float, v_y: float) -> tuple[float, float]:
        """The force [N] at time tau [s] and interface state e [m], v [m/s] (the compiled step's formula)."""
        t, fx, fy, ax, ay, bx, by, ex0, ey0, vx0, vy0, kxx, kxy, kyy, cxx, cxy, cyy = self.coefficients
        s = tau - t
        dx, dy, dvx, dvy = e_x - ex0, e_y - ey0, v_x - vx0, v_y - vy0
        return (fx + s * (ax + s * bx) + kxx * dx + kxy * dy + cxx * dvx + cxy * dvy,
                fy + s * (ay + s * by) + kxy * dx + kyy * dy + cxy * dvx + cyy * dvy)


class Scheme:
    """Base: holds the last exchanges and returns the force (model) for the current step."""

    name = "base"
    ordering = "gauss-seidel"
    uses_tangent = False
    history = 1
    #: ring speeds the master sends the component: "end" (end-of-step values) or "secant"
    #: ((theta(t_n + h) - theta(t_n)) / h, so that the component's cage angle is exact; implicit.py)
    ring_speeds = "end"
    #: True: the master repeats each step with rollback until ``converged`` (``set_trial`` gets the last pass)
    iterative = False
    #: True: the scheme's force model is the component's law (law_model.py); the master hands it the law
    #: (``bind_law``) at the start, the cage angle and ring speeds at t_n (``set_cage``) before each step and the
    #: step's RK4 substeps (``set_substeps``)
    uses_law = False

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

    def substep_tangent(self) -> Exchanged:
        """The exchange whose tangent matrices the master sizes this step's substeps by (``master.substeps``;
        called after ``begin_step``): the last one."""
        return self.past[-1]

    def force_model(self, t0: float, h: float) -> ForceModel | None:
        """This step's force as a ``ForceModel`` (called after ``begin_step(t0, h)``), or None if the
        scheme's force is not of that form (the master then calls ``force``)."""
        return None
