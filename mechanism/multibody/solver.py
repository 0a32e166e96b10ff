"""Generic planar multibody solver for a :class:`mechanism.multibody.model.Model`.

Equations (Xu et al. 2012, Section 2):

* constraints Phi(q, t) = 0                                            eq. (3)
* velocities  Phi_q qd = -Phi_t                                        eq. (4)
* accelerations Phi_q qdd = gamma,
  gamma = -(Phi_q qd)_q qd - 2 Phi_qt qd - Phi_tt                      eq. (5)
* motion [[M, Phi_q^T], [Phi_q, 0]] [qdd; lam] = [Q^A; gamma*]         eq. (9)
  with Baumgarte's gamma* = gamma - 2 alpha Phi_dot - beta^2 Phi
* joint reactions Q^C = -Phi_q^T lam                                   eq. (7)

Implementation notes
--------------------
Planar vectors are handled as complex numbers (x + i y): a body rotation is
exp(i theta), a +90 deg turn is a multiplication by i.

Every kinematic joint is reduced to two kinds of scalar rows, which are evaluated
for all joints at once with precomputed index arrays (no Python loop over joints in
the hot path):

* *point rows*  Phi = Re(conj(n) d),  d = r_J^P - r_I^P,  n = A_ref n'
  (revolute: n' = 1 and i with ref = ground; translational: n' = axis turned +90 deg,
  ref = body i);
* *angle rows*  Phi = theta_J - theta_I - c0 - omega t
  (translational rotation lock: omega = 0; driver: I = ground).

Ground is stored as an extra pseudo-body with zero coordinates at the end of
extended coordinate buffers; its Jacobian columns are written and ignored.

Internally the rows are ordered [point rows, angle rows]; every public result
(Phi, Phi_q, gamma, lambda) is in *model order*: joints in ``model.joints`` order,
each joint's rows in the order given in :mod:`mechanism.multibody.model`.

A System holds scratch buffers: it is not thread-safe.
"""
from __future__ import annotations

import math

import numpy as np

from mechanism.multibody.model import (
    GROUND,
    N_EQUATIONS,
    AngleDriver,
    Joint,
    Model,
    Point,
    Revolute,
    Translational,
)

DEFAULT_ALPHA = 100.0
"""Default Baumgarte damping parameter alpha [1/s] (see :class:`System`)."""
DEFAULT_BETA = 100.0
"""Default Baumgarte stiffness parameter beta [1/s] (see :class:`System`)."""



def _dposv():
    """LAPACK's dposv (Cholesky solve), imported on first use: scipy's import is not paid by the compiled path."""
    global _DPOSV
    if _DPOSV is None:
        from scipy.linalg import lapack
        _DPOSV = lapack.dposv
    return _DPOSV


_DPOSV = None

class System:
    """Equations of motion of a planar multibody model (eq. 3-9).

    Parameters
    ----------
    model: the mechanism as data.
    alpha, beta: Baumgarte parameters [1/s] of gamma* = gamma - 2 alpha Phi_dot - beta^2 Phi,
        so that the constraint error obeys Phi'' + 2 alpha Phi' + beta^2 Phi = 0.
        The paper gives no values. Default alpha = beta = 100 1/s:

        * alpha = beta makes the error dynamics critically damped (no overshoot);
        * 1/beta = 10 ms is about one radian of crank rotation at the fastest speed
          studied (1200 rpm, omega = 126 rad/s): drift is pulled back within a
          fraction of a revolution, and a steady integration residual r leaves an
          error of only about r / beta^2;
        * the added eigenvalues (-100 1/s, double) are far inside RK4's stability
          region for any step used here (h beta = 1e-3 at h = 1e-5 s, 0.1 at 1e-3 s),
          and far below the bearing's contact frequencies (kHz), so the
          stabilisation adds no stiffness and does not interact with them;
        * measured on the ideal slider-crank at 1200 rpm over 10 revolutions (RK4):
          alpha = beta = 0, 10, 100, 1000 1/s gave max |Phi| = 3.4e-11, 3.7e-11, 4.0e-12,
          4.0e-13 at h = 1e-5 s and 5.4e-9, 4.2e-10, 1.1e-11, 6.9e-10 at h = 1e-4 s, with
          slider-acceleration errors 9e-8, 4e-8, 4e-9, 4e-7 m/s^2 (h = 1e-5 s) and
          2.5e-6, 2.4e-7, 7.8e-7, 3.8e-3 m/s^2 (h = 1e-4 s): 100 1/s is accurate at both
          steps, while 1000 1/s amplifies rounding noise into the accelerations.

    Attributes
    ----------
    n: number of coordinates (3 per body, ``model.bodies`` order, q = [x1, y1, th1, ...]).
    m: number of constraint equations.
    mass: diagonal of the mass matrix M, [m1, m1, J1, m2, ...] (kg, kg m^2).
    """

    def __init__(self, model: Model, alpha: float = DEFAULT_ALPHA, beta: float = DEFAULT_BETA):
        self.model = model
        self.alpha = alpha
        self.beta = beta
        self._index = {b.name: k for k, b in enumerate(model.bodies)}
        self._index[GROUND] = len(model.bodies)
        nb = len(model.bodies)
        self.n = 3 * nb
        self.mass = np.array([v for b in model.bodies for v in (b.mass, b.mass, b.inertia)], float)
        self._minv = 1.0 / self.mass
        self._gravity_force = np.zeros(self.n)
        self._gravity_force[0::3] = self.mass[0::3] * model.gravity[0]
        self._gravity_force[1::3] = self.mass[1::3] * model.gravity[1]
        self._build_rows(model.joints)
        self._allocate(nb)

    # ------------------------------------------------------------------ set-up
    def _build_rows(self, joints: tuple[Joint, ...]) -> None:
        """Split the joints into point rows and angle rows; remember the row maps."""
        point_rows: list[tuple[int, Point, Point, str, complex]] = []   # (model row, J, I, ref body, n')
        angle_rows: list[tuple[int, str, str, float, float]] = []          # (model row, J, I, c0, omega)
        self._rows: dict[str, slice] = {}
        row = 0
        for joint in joints:
            self._rows[joint.name] = slice(row, row + N_EQUATIONS[type(joint)])
            if isinstance(joint, Revolute):
                point_rows.append((row, joint.j, joint.i, GROUND, 1.0 + 0j))
                point_rows.append((row + 1, joint.j, joint.i, GROUND, 1j))
            elif isinstance(joint, Translational):
                axis = complex(*joint.axis)
                point_rows.append((row, joint.j, joint.i, joint.i.body, 1j * axis / abs(axis)))
                angle_rows.append((row + 1, joint.j.body, joint.i.body, joint.angle0, 0.0))
            elif isinstance(joint, AngleDriver):
                angle_rows.append((row, joint.body, GROUND, joint.theta0, joint.omega))
            row += N_EQUATIONS[type(joint)]
        self.m = row
        self._K = len(point_rows)
        idx = self._index
        self._bJ = np.array([idx[r[1].body] for r in point_rows], dtype=np.intp)
        self._bI = np.array([idx[r[2].body] for r in point_rows], dtype=np.intp)
        self._sJ = np.array([complex(*r[1].local) for r in point_rows], complex)
        self._sI = np.array([complex(*r[2].local) for r in point_rows], complex)
        self._bref = np.array([idx[r[3]] for r in point_rows], dtype=np.intp)
        self._nprime = np.array([r[4] for r in point_rows], complex)
        # the reference frame rotates with body I (translational) or is ground (revolute)
        self._ref_is_I = np.array([float(r[3] != GROUND) for r in point_rows])
        self._moving_ref = bool(self._ref_is_I.any())
        self._nprime_conj = self._nprime.conj()
        self._aJ = np.array([idx[r[1]] for r in angle_rows], dtype=np.intp)
        self._aI = np.array([idx[r[2]] for r in angle_rows], dtype=np.intp)
        self._c0 = np.array([r[3] for r in angle_rows], float)
        self._omega = np.array([r[4] for r in angle_rows], float)
        internal_to_model = [r[0] for r in point_rows] + [r[0] for r in angle_rows]
        self._to_model = np.argsort(np.array(internal_to_model, dtype=np.intp))  # model[k] = internal[_to_model[k]]
        self._from_model = np.array(internal_to_model, dtype=np.intp)           # internal[k] = model[_from_model[k]]

    def _allocate(self, nb: int) -> None:
        """Preallocate the extended coordinate buffers, complex views and the Jacobian."""
        ne = 3 * (nb + 1)                     # + ground pseudo-body, always zero
        self._qe = np.zeros(ne)
        self._qde = np.zeros(ne)
        # z[k] = x_k + i y_k as a strided complex view of the coordinate buffer
        self._z = np.ndarray((nb + 1,), np.complex128, buffer=self._qe, strides=(24,))
        self._zd = np.ndarray((nb + 1,), np.complex128, buffer=self._qde, strides=(24,))
        self._th = self._qe[2::3]
        self._thd = self._qde[2::3]
        K, m = self._K, self.m
        # G = d(d)/dq for the point rows (complex, extended columns); constant parts now
        self._G = np.zeros((K, ne), complex)
        rk = np.arange(K)
        self._G[rk, 3 * self._bJ] = 1.0
        self._G[rk, 3 * self._bJ + 1] = 1j
        self._G[rk, 3 * self._bI] = -1.0
        self._G[rk, 3 * self._bI + 1] = -1j
        self._G_flat = self._G.reshape(-1)              # a view
        self._G_thJ = rk * ne + 3 * self._bJ + 2        # flat indices of the theta entries
        self._G_thI = rk * ne + 3 * self._bI + 2
        self._Je = np.zeros((m, ne))                    # internal row order
        ra = K + np.arange(len(self._aJ))
        self._Je[ra, 3 * self._aJ + 2] = 1.0
        self._Je[ra, 3 * self._aI + 2] = -1.0
        self._J = self._Je[:, : self.n]                 # view without the ground columns
        self._phi_i = np.zeros(m)
        self._gam_i = np.zeros(m)                       # angle rows: gamma = 0
        self._phit_i = np.zeros(m)
        self._phit_i[K:] = -self._omega                 # Phi_t of the angle rows

    # ------------------------------------------------------------------ kinematics kernel
    def _kinematics(self, q: np.ndarray, qd: np.ndarray, t: float) -> None:
        """Fill Phi, Phi_q and gamma (internal row order) for the state (q, qd, t)."""
        self._qe[: self.n] = q
        self._qde[: self.n] = qd
        th, thd, z = self._th, self._thd, self._z
        bJ, bI, bref = self._bJ, self._bI, self._bref
        K = self._K
        rot = np.exp(1j * th)                                   # A_k as exp(i theta_k)
        uJ = rot[bJ] * self._sJ                                 # A_k s'_k (eq. 10)
        uI = rot[bI] * self._sI
        d = (z[bJ] - z[bI]) + (uJ - uI)                         # r_J^P - r_I^P
        wJ, wI = thd[bJ], thd[bI]
        wuJ, wuI = wJ * uJ, wI * uI
        dcen = wJ * wuJ - wI * wuI                              # -(relative centripetal accel.)
        # conj(n), n = A_ref n' (constant when every reference frame is ground)
        cn = (rot[bref] * self._nprime).conj() if self._moving_ref else self._nprime_conj
        phi_p = (cn * d).real
        self._phi_i[:K] = phi_p                                 # eq. (3)
        G = self._G_flat
        G[self._G_thJ] = 1j * uJ
        if self._moving_ref:
            # eq. (5): gamma = -d2/dt2 Re(conj(n) d) at qdd = 0, n turning with body I
            wr = thd[bref]
            dd = (self._zd[bJ] - self._zd[bI]) + 1j * (wuJ - wuI)    # relative point velocity
            self._gam_i[:K] = wr * wr * phi_p + (cn * (dcen + 2j * wr * dd)).real
            G[self._G_thI] = -1j * (uI + self._ref_is_I * d)         # + rotation of n
        else:
            self._gam_i[:K] = (cn * dcen).real                      # eq. (5), fixed n
            G[self._G_thI] = -1j * uI
        self._Je[:K] = (cn[:, None] * self._G).real
        self._phi_i[K:] = th[self._aJ] - th[self._aI] - (self._c0 + self._omega * t)

    # ------------------------------------------------------------------ public API
    def slice(self, body: str) -> slice:
        """Slice of ``body``'s coordinates [x, y, theta] in q."""
        if body == GROUND:
            raise KeyError("ground has no coordinates")
        k = self._index[body]
        return slice(3 * k, 3 * k + 3)

    def rows(self, joint_name: str) -> slice:
        """Slice of a joint's equations in Phi (model order), hence of its multipliers."""
        return self._rows[joint_name]

    def point_state(self, q: np.ndarray, qd: np.ndarray | None, point: Point) -> tuple[float, float, float, float]:
        """(x, y, xd, yd) of a point as floats: r^P = r + A s' (eq. 10), rd^P = rd + thd B s' (eq. 11-12).

        The scalar fast path of ``point_position``/``point_velocity`` (one home for both);
        velocities are 0 if ``qd`` is None.
        """
        if point.body == GROUND:
            return float(point.local[0]), float(point.local[1]), 0.0, 0.0
        i = 3 * self._index[point.body]
        th = float(q[i + 2])
        c, s = math.cos(th), math.sin(th)
        sx, sy = point.local
        ux, uy = c * sx - s * sy, s * sx + c * sy
        if qd is None:
            return float(q[i]) + ux, float(q[i + 1]) + uy, 0.0, 0.0
        thd = float(qd[i + 2])
        return float(q[i]) + ux, float(q[i + 1]) + uy, float(qd[i]) - thd * uy, float(qd[i + 1]) + thd * ux

    def point_position(self, q: np.ndarray, point: Point) -> np.ndarray:
        """Global position r^P = r + A s' [m] of a point (eq. 10)."""
        return np.array(self.point_state(q, None, point)[:2])

    def point_velocity(self, q: np.ndarray, qd: np.ndarray, point: Point) -> np.ndarray:
        """Global velocity rd^P = rd + thd B s' [m/s] of a point (eq. 11-12).

        Linear in qd: passing accelerations with zero velocities gives rdd + thdd B s'.
        """
        return np.array(self.point_state(q, qd, point)[2:])

    def phi(self, q: np.ndarray, t: float) -> np.ndarray:
        """Constraint violations Phi(q, t) (eq. 3), model order [m, rad]."""
        self._kinematics(q, np.zeros(self.n), t)
        return self._phi_i[self._to_model].copy()

    def jacobian(self, q: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Constraint Jacobian Phi_q (m x n), model order."""
        self._kinematics(q, np.zeros(self.n), t)
        return self._J[self._to_model].copy()

    def phi_t(self, t: float = 0.0) -> np.ndarray:
        """Partial time derivative Phi_t (model order); constant for these joints."""
        return self._phit_i[self._to_model].copy()

    def gamma(self, q: np.ndarray, qd: np.ndarray, t: float) -> np.ndarray:
        """Right-hand side gamma of eq. (5), without Baumgarte terms, model order."""
        self._kinematics(q, qd, t)
        return self._gam_i[self._to_model].copy()

    def applied_forces(self, q: np.ndarray, qd: np.ndarray, t: float) -> np.ndarray:
        """Generalized applied forces Q^A of gravity [N, N, N m] (a new array)."""
        return self._gravity_force.copy()

    def point_force(self, q: np.ndarray, point: Point, force: np.ndarray,
                    at: np.ndarray | None = None) -> np.ndarray:
        """Generalized force (n-vector) of a planar force [N] applied to ``point``'s body.

        The force acts at the point, or at the global position ``at`` [m] if given:
        [Fx, Fy, ((r_at - r_body) x F)_z] in the body's slot; zero for GROUND.
        """
        Q = np.zeros(self.n)
        self.add_point_force(Q, q, point, float(force[0]), float(force[1]), at)
        return Q

    def add_point_force(self, Q: np.ndarray, q: np.ndarray, point: Point, fx: float, fy: float,
                        at: tuple[float, float] | np.ndarray | None = None) -> None:
        """Add to Q (in place) the generalized force of (fx, fy) [N] at ``point`` or at the global ``at``."""
        if point.body == GROUND:
            return
        i = 3 * self._index[point.body]
        ax, ay = self.point_state(q, None, point)[:2] if at is None else (float(at[0]), float(at[1]))
        Q[i] += fx
        Q[i + 1] += fy
        Q[i + 2] += (ax - float(q[i])) * fy - (ay - float(q[i + 1])) * fx

    def accelerations(self, q: np.ndarray, qd: np.ndarray, t: float,
                      Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Solve eq. (9) with Baumgarte stabilisation: (qdd, lambda [model order]).

        Q: generalized applied forces (n,). With M diagonal the multipliers come from
        the Schur complement (Phi_q M^-1 Phi_q^T) lam = Phi_q M^-1 Q - gamma*,
        then qdd = M^-1 (Q - Phi_q^T lam).
        """
        minv = self._minv
        if self.m == 0:
            return minv * Q, np.zeros(0)
        self._kinematics(q, qd, t)
        J = self._J
        JM = J * minv
        phid = J @ qd + self._phit_i                                   # Phi_dot, eq. (4)
        rhs = JM @ Q - self._gam_i + self._2alpha * phid + self._beta2 * self._phi_i
        _, lam, info = _dposv()(JM @ J.T, rhs)
        if info != 0:                                                  # redundant constraints
            lam = np.linalg.lstsq(JM @ J.T, rhs, rcond=None)[0]
        qdd = minv * Q - JM.T @ lam
        return qdd, lam[self._to_model]

    @property
    def alpha(self) -> float:
        """Baumgarte damping parameter alpha [1/s]."""
        return self._alpha

    @alpha.setter
    def alpha(self, value: float) -> None:
        self._alpha = float(value)
        self._2alpha = 2.0 * self._alpha

    @property
    def beta(self) -> float:
        """Baumgarte stiffness parameter beta [1/s]."""
        return self._beta

    @beta.setter
    def beta(self, value: float) -> None:
        self._beta = float(value)
        self._beta2 = self._beta * self._beta

    def multipliers(self, lam: np.ndarray, joint_name: str) -> np.ndarray:
        """The Lagrange multipliers of one joint (model order lam)."""
        return np.array(lam[self._rows[joint_name]], float)

    def reactions(self, q: np.ndarray, lam: np.ndarray) -> dict[str, np.ndarray]:
        """Generalized reaction forces Q^C = -Phi_q^T lam of each joint (eq. 7).

        Each value is an n-vector; its slot for a body is [Fx, Fy, Mz about the
        centre of mass] that the joint applies to that body [N, N, N m].
        """
        J = self.jacobian(q)
        return {name: -J[sl].T @ lam[sl] for name, sl in self._rows.items()}

    def driving_moment(self, lam: np.ndarray, driver_name: str) -> float:
        """Counter-clockwise moment [N m] the driver applies to its body.

        Phi = theta - theta0 - omega t has Phi_q = +1 at theta, so Q^C = -lam (eq. 7).
        """
        if not isinstance(self.model.joint(driver_name), AngleDriver):
            raise TypeError(f"{driver_name!r} is not an AngleDriver")
        return -float(lam[self._rows[driver_name].start])

    def assemble(self, q_guess: np.ndarray, t: float, tol: float = 1e-12,
                 max_iter: int = 50) -> np.ndarray:
        """Positions satisfying Phi(q, t) = 0 (eq. 3) by Newton-Raphson from q_guess.

        Uses the minimum-norm Newton step, so an under-constrained model (free
        relative degrees of freedom) moves as little as possible from the guess.
        Raises RuntimeError without convergence to max |Phi| <= tol.
        """
        q = np.array(q_guess, float)
        for _ in range(max_iter):
            phi = self.phi(q, t)
            if self.m == 0 or np.max(np.abs(phi)) <= tol:
                return q
            q -= np.linalg.lstsq(self.jacobian(q, t), phi, rcond=None)[0]
        raise RuntimeError(f"assembly did not converge: max|Phi| = {np.max(np.abs(phi)):.3e}")

    def velocities(self, q: np.ndarray, t: float, qd_guess: np.ndarray | None = None) -> np.ndarray:
        """Velocities satisfying Phi_q qd = -Phi_t (eq. 4).

        The minimum-norm correction of qd_guess (zero if None): unique when m == n.
        """
        qd = np.zeros(self.n) if qd_guess is None else np.array(qd_guess, float)
        if self.m == 0:
            return qd
        J = self.jacobian(q, t)
        return qd + np.linalg.lstsq(J, -self.phi_t(t) - J @ qd, rcond=None)[0]

    def kinetic_energy(self, qd: np.ndarray) -> float:
        """Kinetic energy T = qd^T M qd / 2 [J]."""
        return 0.5 * float(self.mass @ (qd * qd))
