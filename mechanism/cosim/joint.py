"""The bearing joint seen from the multibody side: its inputs (eq. 10-12, 16) and its loads (eq. 13-15, 20-23).

Body i carries the housing (outer ring), body j the journal (inner ring). The component
returns F, the force on the housing; the journal receives -F.

Where the force acts (``contact_points``):

* ``"centres"`` (default): at the ring centres P_i, P_j. A frictionless ball force is radial,
  so every ball force passes through both ring centres and so does their resultant; this is
  the exact moment of the bearing model on the two bodies.
* ``"eq15"``: at the paper's contact points r^Q_k = r^P_k + R_k n, n = e/|e| (eq. 13-15), with
  R_k the housing and journal radii, giving the transport moments of eq. (21) and (23). This
  is the paper's choice, inherited from journal-bushing clearance joints; with a ball
  bearing it adds a moment (R_k n) x f_k that the balls cannot transmit. Kept as an option.
"""
from __future__ import annotations

import math

import numpy as np

from mechanism.multibody.model import BearingJoint
from mechanism.multibody.solver import System

CONTACT_POINTS = ("centres", "eq15")


class BearingLink:
    """Maps the mechanism's state to the bearing's inputs, and the bearing's force to generalized forces."""

    def __init__(self, system: System, joint: BearingJoint, contact_points: str = "centres"):
        if contact_points not in CONTACT_POINTS:
            raise ValueError(f"contact_points must be one of {CONTACT_POINTS}, not {contact_points!r}")
        self.system, self.joint, self.contact_points = system, joint, contact_points
        self._theta_i = system.slice(joint.housing.body).start + 2
        self._theta_j = system.slice(joint.journal.body).start + 2

    def inputs(self, q: np.ndarray, qd: np.ndarray) -> tuple[float, float, float, float, float, float]:
        """(e_x, e_y, v_x, v_y, omega_inner, omega_outer): eq. (10)-(12), ring speeds for eq. (16)."""
        xi, yi, vxi, vyi = self.system.point_state(q, qd, self.joint.housing)
        xj, yj, vxj, vyj = self.system.point_state(q, qd, self.joint.journal)
        return xj - xi, yj - yi, vxj - vxi, vyj - vyi, float(qd[self._theta_j]), float(qd[self._theta_i])

    def ring_angles(self, q: np.ndarray) -> tuple[float, float]:
        """(theta_journal, theta_housing) [rad]: the absolute angles of the inner and outer ring bodies."""
        return float(q[self._theta_j]), float(q[self._theta_i])

    def secant_ring_speeds(self, u: tuple, q0: np.ndarray, q1: np.ndarray, h: float) -> tuple:
        """``u`` with its ring speeds replaced by (theta(t + h) - theta(t)) / h of journal and housing:
        held over the step, they make the component's cage angle (eq. 16 integrated) exact."""
        return (*u[:4], float(q1[self._theta_j] - q0[self._theta_j]) / h,
                float(q1[self._theta_i] - q0[self._theta_i]) / h)

    def generalized_force(self, q: np.ndarray, e_x: float, e_y: float, F_x: float, F_y: float,
                          Q: np.ndarray | None = None) -> np.ndarray:
        """Generalized forces of F on the housing body and -F on the journal body, eq. (20)-(23).

        Added into ``Q`` in place if given (and returned), else into a new vector.
        """
        s, jt = self.system, self.joint
        Q = np.zeros(s.n) if Q is None else Q
        at_i = at_j = None
        if self.contact_points == "eq15":
            e = math.hypot(e_x, e_y)
            if e > 0.0:
                nx, ny = e_x / e, e_y / e                                            # eq. (14)
                xi, yi = s.point_state(q, None, jt.housing)[:2]
                xj, yj = s.point_state(q, None, jt.journal)[:2]
                at_i = (xi + jt.housing_radius * nx, yi + jt.housing_radius * ny)    # eq. (15)
                at_j = (xj + jt.journal_radius * nx, yj + jt.journal_radius * ny)
        s.add_point_force(Q, q, jt.housing, F_x, F_y, at_i)                           # eq. (20)-(21)
        s.add_point_force(Q, q, jt.journal, -F_x, -F_y, at_j)                         # eq. (22)-(23)
        return Q

    def mobility(self, q: np.ndarray, t: float) -> float:
        """Largest eigenvalue [1/kg] of the 2x2 map from an action-reaction pair at the rings to the
        relative acceleration of the ring centres, for the constrained mechanism at q (qd = 0).

        sqrt(k * mobility) estimates the contact's natural frequency for a tangent stiffness k;
        the master uses it to choose substeps.
        """
        s = self.system
        qd = np.zeros(s.n)
        base = s.accelerations(q, qd, t, np.zeros(s.n))[0]
        cols = []
        for unit in ((1.0, 0.0), (0.0, 1.0)):
            Q = self.generalized_force(q, 0.0, 0.0, -unit[0], -unit[1])   # -F on housing = +unit on journal
            qdd = s.accelerations(q, qd, t, Q)[0] - base
            # with qd = 0 a point's acceleration is r'' + theta'' B s', i.e. point_velocity with qdd in place of qd
            a = s.point_velocity(q, qdd, self.joint.journal) - s.point_velocity(q, qdd, self.joint.housing)
            cols.append(a)
        G = np.column_stack(cols)
        G = 0.5 * (G + G.T)
        return float(np.max(np.linalg.eigvalsh(G)))
