"""Second-order interface-Jacobian coupling: secant ring speeds, and the iterated (strong) variant with rollback.

Two schemes share one force model over a communication step [t_n, t_n + h], s = tau - t_n:

    F(tau, e, v) = F_n + d s + K (e - e_n) + C (v - v_n)                       (affine: ``ForceModel``)

``jacobian-secant`` (explicit, one component call per step)
    K = K_n, C = C_n (the component's tangent stiffness and damping at t_n) and d the drift of the
    *previous* step, the force change K and C did not explain (as ``jacobian-drift``):
        d = [F_n - F_{n-1} - K_{n-1}(e_n - e_{n-1}) - C_{n-1}(v_n - v_{n-1})] / (t_n - t_{n-1}).

``jacobian-implicit`` (iterated to a fixed point with rollback, >= 2 component calls per step)
    pass 0 is ``jacobian-secant``; after each pass the component has returned the end-of-step
    exchange x* = (e*, v*, F*, K*, C*) for the state the pass reached; the step is rolled back
    (mechanism state and FMU state, ``getFMUstate``/``setFMUstate``) and repeated with
        K = (K_n + K*)/2,  C = (C_n + C*)/2,
        d = [F* - F_n - K (e* - e_n) - C (v* - v_n)] / h,
    the model through both ends: F(t_n, e_n, v_n) = F_n and F(t_n + h, e*, v*) = F*, plus, for each
    force jump J at t_n + theta h in the step (a contact onset with constant damping, ``onset_jumps``),
    the term J (3 - 6 theta)(s/h - s^2/h^2), zero at both ends, which gives the jump its exact impulse
    J (1 - theta) h instead of the linear ramp's J h/2 (an O(h) error per onset otherwise): the force
    *of this step* (the trapezoidal rule of the interface force, linearly implicit in e and v
    through K and C) instead of one extrapolated from the last. The pass repeats until the
    end-of-step force and eccentricity of two passes agree to ``MasterSettings.iteration_tol``
    (relative to max(|F|, 1 N) and to the radial clearance per side), at most
    ``MasterSettings.max_iterations`` passes; the master reports passes per step.

Both send the component, instead of the end-of-step ring speeds, their *secant* values
(theta(t_n + h) - theta(t_n)) / h: the FMU integrates the cage angle with the ring speeds held
over the step (eq. 16, ``BallBearing.advance_cage``), which with the end-of-step speeds is the
backward Euler rule, O(h) in the cage angle (issue 12: the cage-angle error halved with the
step). The cage speed of eq. (16) is linear in the ring speeds, so the cage angle is the same
linear combination of the ring *angles* and the secant speeds make the FMU's cage angle exact up
to the mechanism's own error. With the constant-damping model the ring speeds enter nothing
else; with the oil-film model (eq. 29-32) they also set the entrainment speed, which then is
the step's mean speed, an O(h^2) difference (docs/coupling.md).
"""
from __future__ import annotations

import math

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import DAMPING_CONSTANT

from .base import Exchanged, ForceModel
from .jacobian import InterfaceJacobianDrift, _linear

#: (theta, J_x, J_y): a force jump J [N] at t_n + theta h within the step (a contact onset or release)
Jump = tuple[float, float, float]


def ball_deflections(bearing: BallBearing, e_x: float, e_y: float, cage_angle: float,
                     angles: list[float] | None = None) -> list[float]:
    """delta_r = e . u_r - P_d/2 [m] of every ball (eq. 18's bracket; u_r at the ball angles of eq. 17):
    > 0 in the load zone. Used to locate contact onsets (here and in ``mechanism.cosim.monolithic``).
    ``angles``: ``bearing.ball_angles(cage_angle)`` when the caller has them already."""
    if angles is None:
        angles = bearing.ball_angles(cage_angle)
    return [bearing.deflection(e_x, e_y, p) for p in angles]


def onset_jumps(bearing: BallBearing, a: Exchanged, cage_a: float, b: Exchanged, cage_b: float) -> list[Jump]:
    """The jumps of the bearing force within a step from the exchange ``a`` to ``b`` (cage angles [rad]).

    With constant damping (eq. 18) a ball entering the load zone (delta_r from <= 0 to > 0) switches its
    damping force C v_r on at once, clamped at zero (a contact cannot pull): a jump of
    C max(v_r, 0) u_r; one leaving it, the opposite. The crossing is located by linear interpolation of
    delta_r = e . u_r - P_d/2 between the step's ends (an O(h^2) error in time), the ball angles from
    ``BallBearing.ball_angles`` (eq. 17). The oil-film damping vanishes with the load: no jump.
    """
    if bearing.damping_model != DAMPING_CONSTANT or bearing.damping_coefficient == 0.0:
        return []
    C = bearing.damping_coefficient
    jumps = []
    angles_a, angles_b = bearing.ball_angles(cage_a), bearing.ball_angles(cage_b)
    for pa, pb, da, db in zip(angles_a, angles_b, ball_deflections(bearing, a.e_x, a.e_y, cage_a, angles_a),
                              ball_deflections(bearing, b.e_x, b.e_y, cage_b, angles_b)):
        if (da > 0.0) == (db > 0.0):
            continue
        theta = da / (da - db)
        phi = pa + theta * (pb - pa)
        ux, uy = math.cos(phi), math.sin(phi)
        vr = (a.v_x + theta * (b.v_x - a.v_x)) * ux + (a.v_y + theta * (b.v_y - a.v_y)) * uy
        jump = C * max(vr, 0.0) * (1.0 if da <= 0.0 else -1.0)
        if jump != 0.0:
            jumps.append((theta, jump * ux, jump * uy))
    return jumps


class InterfaceJacobianSecant(InterfaceJacobianDrift):
    """``jacobian-drift`` with secant ring speeds sent to the component (its cage angle second order)."""

    name = "jacobian-secant"
    ring_speeds = "secant"


class InterfaceJacobianImplicit(InterfaceJacobianSecant):
    """The step's own drift and the mean tangent matrices, iterated with rollback to a fixed point."""

    name = "jacobian-implicit"
    iterative = True

    def __init__(self):
        super().__init__()
        self.trial: Exchanged | None = None
        self.jumps: list[Jump] = []

    def set_trial(self, x: Exchanged | None, jumps: list[Jump] = ()) -> None:
        """The end-of-step exchange of the last pass (None: the first pass, extrapolated drift) and the
        force jumps within the step it implies (``onset_jumps``)."""
        self.trial, self.jumps = x, list(jumps)

    def begin_step(self, t: float, h: float) -> None:
        super().begin_step(t, h)
        x = self.trial
        if x is None:
            self._model = ForceModel.linear(self.past[-1], self._drift)
            return
        a = self.past[-1]
        k = (0.5 * (a.k_xx + x.k_xx), 0.5 * (a.k_xy + x.k_xy), 0.5 * (a.k_yy + x.k_yy))
        c = (0.5 * (a.c_xx + x.c_xx), 0.5 * (a.c_xy + x.c_xy), 0.5 * (a.c_yy + x.c_yy))
        mean = Exchanged(a.t, a.e_x, a.e_y, a.v_x, a.v_y, a.F_x, a.F_y, *k, *c)
        predicted = _linear(mean, x.e_x, x.e_y, x.v_x, x.v_y)
        dt = x.t - a.t
        self._drift = ((x.F_x - predicted[0]) / dt, (x.F_y - predicted[1]) / dt)
        # a jump J at t_n + theta h: the linear drift carries it as J s/h, whose impulse is J h/2; the
        # quadratic J (3 - 6 theta)(s/h - s^2/h^2) (zero at both ends) makes it J (1 - theta) h, the jump's
        a2x = a2y = 0.0
        ax, ay = self._drift
        for theta, jx, jy in self.jumps:
            g = 3.0 - 6.0 * theta
            ax, ay = ax + g * jx / dt, ay + g * jy / dt
            a2x, a2y = a2x - g * jx / (dt * dt), a2y - g * jy / (dt * dt)
        self._model = ForceModel(mean.t, (mean.F_x, mean.F_y), (ax, ay), (a2x, a2y), (mean.e_x, mean.e_y),
                                 (mean.v_x, mean.v_y), k, c)

    def force(self, tau, e_x, e_y, v_x, v_y):
        return self._model(tau, e_x, e_y, v_x, v_y)

    def force_model(self, t0, h):
        return self._model

    @staticmethod
    def converged(a: Exchanged, b: Exchanged, tol: float, e_scale: float) -> bool:
        """Two passes' end-of-step force and eccentricity agree to ``tol`` (relative)."""
        f_scale = max(1.0, abs(b.F_x), abs(b.F_y))
        return (abs(a.F_x - b.F_x) <= tol * f_scale and abs(a.F_y - b.F_y) <= tol * f_scale
                and abs(a.e_x - b.e_x) <= tol * e_scale and abs(a.e_y - b.e_y) <= tol * e_scale)
