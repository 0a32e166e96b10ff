"""Model-based coupling (``law-model``): the component's own force law as the interface model within a step.

The interface-Jacobian schemes continue the exchanged force along the component's tangent matrices,
F_n + K (e - e_n) + C (v - v_n), a LINEAR model; over a coarse step (1e-4 s, two or three steps per period
of the 3.6-5.8 kHz contact ringing) the deflection changes a lot within the step and Hertz's exponent 1.5
makes that model poor (docs/coupling.md, "At 1e-4 s"). When the master knows the component's law (the ball
bearing's eq. 18-19, whose parameters the master sets itself, ``fmu_bearing.ball_bearing.BallBearing``), it
can integrate the step with that law instead, the component's exchanged force correcting it:

    F(tau, e, v) = F_law(e, v; phi(tau)) + c_n + (c* - c_n) s / h,     s = tau - t_n,

    c_n = F_n - F_law(e_n, v_n; phi_n)       (the component's force at t_n against the law there)
    c*  = F* - F_law(e*, v*; phi*)           (the same at the end of the last pass; 0 on pass 0)
    phi(tau) = phi_n + omega_m s              (the cage angle, eq. 16 with the ring speeds at t_n)

where phi_n is the kinematic cage angle at t_n (``energy.kinematic_cage_angle``, which the component's cage
angle equals with secant ring speeds) and omega_m = eq. (16) of the ring speeds at t_n. The component stays
the authority at every communication point: F(t_n) = F_n, and after the iterated pass F(t_n + h) = F*.
With an exact law (the in-process component, or an FMU with the same parameters) c_n = c* = 0 and the
coupling error is the master's RK4 error with its substeps; a law that differs from the component's is
corrected at both ends, to first order in between (the linear correction ramp).

The step is iterated with rollback like ``jacobian-implicit`` (``iterative``): pass 0 holds c_n, later passes
ramp to the last pass's c*; ``converged`` compares two passes' end-of-step force and eccentricity, and the first
pass is accepted at once when the master predicts that a second would change nothing (``end_mismatch``: c* - c_n,
no contact onset in the step). The ring speeds sent to the component are the secant ones (implicit.py). The
master's RK4 substeps are sized by the stiffest law tangent met in the step, ``resolution`` times finer than
stability needs (``substep_tangent``), at least ``min_substeps`` per step in contact (the error is the substeps':
they must shrink with the step for the scheme to converge with h), and from the second pass each contact onset gets
a force linear over its substep that makes RK4's impulse and first moment of the force's switch-on exact
(``_onset_corrections``, ``onset_weights``). docs/coupling.md, "Model-based coupling" and "law-model's order".

Needs the law (``bind_law``, from the master's ``contact_law``) and, each step, the cage angle and ring
speeds at t_n (``set_cage``) and the substeps (``set_substeps``); without a law it is ``jacobian-implicit``.
"""
from __future__ import annotations

import math

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import DAMPING_CONSTANT

from .base import Exchanged, sym_eig_max
from .implicit import InterfaceJacobianImplicit


class LawModel(InterfaceJacobianImplicit):
    """The component's force law plus the exchanged correction as the force within a step (iterated)."""

    name = "law-model"
    uses_law = True
    #: substeps per communication step, relative to those RK4's stability needs (``substep_tangent``)
    resolution = 8.0
    #: False: no onset correction (``_onset_corrections``; for measurements)
    onset_correction = True
    #: substeps per communication step at least while the law has a contact in the step (``set_substeps``): the
    #: substep then shrinks with the step and the scheme converges with h (its error is the substeps', about third
    #: order in their width; docs/coupling.md, "law-model's order")
    min_substeps = 4

    def __init__(self):
        super().__init__()
        self.law: BallBearing | None = None
        self._evaluate = None
        self._cage = 0.0             # phi_n [rad]
        self._omega = 0.0            # omega_m [rad/s] (eq. 16 at t_n)
        self._wi = self._wo = 0.0    # ring speeds at t_n [rad/s] (the oil-film law's entrainment speed)
        self._h_step = 1.0
        self._t_n = 0.0
        self._m = 1                  # the master's RK4 substeps in this pass (``set_substeps``)
        self._calls = 0              # force evaluations in this pass: four per RK4 substep, in order
        self._bounds: dict[int, tuple[float, float, float, float]] = {}   # (e, v) at substep starts, this pass
        self._recorded: tuple[int, dict] | None = None                    # (m, bounds) of the last pass
        self._onsets: dict[int, tuple[float, float]] = {}                 # substep -> onset correction [N]
        self._k_seen = 0.0           # the largest eigenvalue of the law's tangent stiffness met in this step [N/m]
        self._tangent = (0.0,) * 6   # its K and C (k_xx, k_xy, k_yy, c_xx, c_xy, c_yy)
        self._c0 = (0.0, 0.0)
        self._c1 = (0.0, 0.0)

    def bind_law(self, law: BallBearing | None) -> None:
        """The component's force law (None: fall back to ``jacobian-implicit``'s force model)."""
        self.law = law
        self._evaluate = None
        if law is not None:
            self._evaluate = law.evaluate
            try:   # the compiled second implementation of the law (tests/test_kernels.py holds it to evaluate)
                import numpy as np

                from mechanism.cosim import law_kernel
                P, out, loads = law_kernel.pack_bearing(law), np.zeros(10), np.zeros(law.n_balls)
                kernel = law_kernel.evaluate

                def evaluate(ex, ey, vx, vy, cage, wi, wo):
                    kernel(P, ex, ey, vx, vy, cage, wi, wo, out, loads)
                    return out
                self._evaluate = evaluate
            except ImportError:    # pragma: no cover - numba missing
                pass

    def set_cage(self, cage_angle: float, omega_inner: float, omega_outer: float) -> None:
        """The kinematic cage angle [rad] and ring speeds [rad/s] at the start t_n of the coming step."""
        self._cage = cage_angle
        self._omega = self.law.cage_velocity(omega_inner, omega_outer) if self.law is not None else 0.0
        self._wi, self._wo = omega_inner, omega_outer

    def _law(self, s: float, e_x: float, e_y: float, v_x: float, v_y: float) -> tuple[float, float]:
        """F_law(e, v; phi_n + omega_m s) [N] (eq. 18-19); keeps the stiffest tangent seen in this step."""
        out = self._evaluate(e_x, e_y, v_x, v_y, self._cage + self._omega * s, self._wi, self._wo)
        k = sym_eig_max(out[2], out[3], out[4])
        if k > self._k_seen:
            self._k_seen, self._tangent = k, (float(out[2]), float(out[3]), float(out[4]),
                                              float(out[5]), float(out[6]), float(out[7]))
        return float(out[0]), float(out[1])

    def begin_step(self, t: float, h: float) -> None:
        super().begin_step(t, h)          # jacobian-implicit's model: the fallback without a law
        if self.law is None:
            return
        a = self.past[-1]
        if self.trial is None:    # a new step: the stiffest tangent so far is the start's or the predicted end's
            self._k_seen, self._tangent = sym_eig_max(a.k_xx, a.k_xy, a.k_yy), (a.k_xx, a.k_xy, a.k_yy,
                                                                             a.c_xx, a.c_xy, a.c_yy)
            self._law(h, a.e_x + h * a.v_x, a.e_y + h * a.v_y, a.v_x, a.v_y)
        fx, fy = self._law(0.0, a.e_x, a.e_y, a.v_x, a.v_y)
        self._c0 = (a.F_x - fx, a.F_y - fy)
        x: Exchanged | None = self.trial
        if x is None:
            self._c1 = self._c0
        else:
            dt = x.t - a.t
            fx, fy = self._law(dt, x.e_x, x.e_y, x.v_x, x.v_y)
            self._c1 = (x.F_x - fx, x.F_y - fy)
        self._h_step, self._t_n = h, a.t
        if self.trial is None:
            self._recorded = None
        elif self._bounds:
            self._recorded = (self._m, self._bounds)
        self._bounds, self._onsets, self._calls = {}, {}, 0

    def set_substeps(self, m: int, cap: int) -> int:
        """The master's RK4 substeps in the coming pass: ``m`` (its stability rule on ``substep_tangent``), at least
        ``min_substeps`` (at most ``cap``) while the law met a contact in the step; returns the count to use. From
        the second pass on, each ball's contact onset in a substep of the last pass (same substeps) gets the onset
        correction of that substep (``_onset_corrections``)."""
        if self._k_seen > 0.0 and m < self.min_substeps:
            m = max(m, min(self.min_substeps, cap))
        self._m = m
        if self.onset_correction and self._recorded is not None and self._recorded[0] == m and self.trial is not None:
            self._onsets = self._onset_corrections(m, self._recorded[1], self.trial)
        return m

    def _onset_corrections(self, m: int, bounds: dict, end: Exchanged) -> dict[int, tuple[float, float, float, float]]:
        """Per substep, the force g0 + g1 sigma (sigma = (tau - t_k) / h_s) that makes RK4's impulse and first moment
        of each contact onset exact.

        A ball entering the load zone at t_k + theta h_s switches its force on at the value j = C v_r (eq. 18, the
        Hertz term starts at zero), growing at d per substep (C dv_r, linear between the substep's ends). RK4 samples
        it at its stages sigma = 0, 1/2 (twice), 1: 0, [theta < 1/2] (j + d (1/2 - theta)), j + d (1 - theta), and
        integrates the velocity with the weights 1/6, 1/3, 1/3, 1/6 and the position with h_s^2 (f_0 + f_1 + f_2) / 6:
        an O(h_s) impulse error per onset (first order) and an O(h_s^2) position error. RK4 integrates a force linear
        in time exactly; ``onset_weights`` gives the g0, g1 that make up both deficits. theta is the root of the cubic
        Hermite interpolant of the ball's deflection delta_r = e . u_r - P_d/2 through its values and rates at the
        substep's ends (``onset_fraction``; of the last pass; the end of the step is ``end``)."""
        law = self.law
        if law.damping_model != DAMPING_CONSTANT or law.damping_coefficient == 0.0:
            return {}
        C, hs, om = law.damping_coefficient, self._h_step / m, self._omega
        points = dict(bounds)
        points[m] = (end.e_x, end.e_y, end.v_x, end.v_y)
        spacing = 2.0 * math.pi / law.n_balls
        out = {}
        for k in range(m):
            a, b = points.get(k), points.get(k + 1)
            if a is None or b is None:
                continue
            pa, pb = self._cage + om * k * hs, self._cage + om * (k + 1) * hs
            g0x = g0y = g1x = g1y = 0.0
            for r in range(law.n_balls):
                ra, rb = pa + r * spacing, pb + r * spacing
                da, db = law.deflection(a[0], a[1], ra), law.deflection(b[0], b[1], rb)
                if not (da <= 0.0 and 0.0 < db):
                    continue
                ma = law.deflection_rate(*a, ra, om) * hs     # d delta_r / d sigma
                mb = law.deflection_rate(*b, rb, om) * hs
                theta = onset_fraction(da, db, ma, mb)
                phi = pa + r * spacing + theta * (pb - pa)
                ux, uy = math.cos(phi), math.sin(phi)
                wa = (a[2] * ux + a[3] * uy) * C
                wb = (b[2] * ux + b[3] * uy) * C
                j = wa + theta * (wb - wa)
                if not j > 0.0:
                    continue
                g0, g1 = onset_weights(theta, j, wb - wa)
                g0x, g0y = g0x + g0 * ux, g0y + g0 * uy
                g1x, g1y = g1x + g1 * ux, g1y + g1 * uy
            if g0x != 0.0 or g0y != 0.0 or g1x != 0.0 or g1y != 0.0:
                out[k] = (g0x, g0y, g1x, g1y)
        return out

    def substep_tangent(self) -> Exchanged:
        """The stiffest tangent of the law met in this step so far (the start, the predicted end e_n + v_n h, every
        force evaluation of the earlier passes), K scaled by ``resolution``^2 and C by ``resolution``: the master
        sizes the substeps by it (``master.substeps``: h_sub (sqrt(k g) + c g) <= substep_limit), so that a step
        that starts out of contact and meets one is subcycled, ``resolution`` times finer than RK4's stability
        needs (the coupling's error is the RK4 error of the contact ringing, chiefly its phase)."""
        a = self.past[-1]
        if self.law is None:
            return a
        r, (kxx, kxy, kyy, cxx, cxy, cyy) = self.resolution, self._tangent
        r2 = r * r
        return Exchanged(a.t, a.e_x, a.e_y, a.v_x, a.v_y, a.F_x, a.F_y, r2 * kxx, r2 * kxy, r2 * kyy,
                         r * cxx, r * cxy, r * cyy)

    def force(self, tau, e_x, e_y, v_x, v_y):
        if self.law is None:
            return self._model(tau, e_x, e_y, v_x, v_y)
        s = tau - self.past[-1].t
        fx, fy = self._law(s, e_x, e_y, v_x, v_y)
        k, stage = divmod(self._calls, 4)          # the master's RK4: four evaluations per substep, in order
        self._calls += 1
        if stage == 0:
            self._bounds[k] = (e_x, e_y, v_x, v_y)
        g = self._onsets.get(k)
        if g is not None:
            sigma = 0.0 if stage == 0 else (1.0 if stage == 3 else 0.5)
            fx, fy = fx + (g[0] + g[2] * sigma), fy + (g[1] + g[3] * sigma)
        r = s / self._h_step
        return (fx + self._c0[0] + r * (self._c1[0] - self._c0[0]),
                fy + self._c0[1] + r * (self._c1[1] - self._c0[1]))

    def force_model(self, t0, h):
        return self._model if self.law is None else None

    def end_mismatch(self, b: Exchanged) -> tuple[float, float] | None:
        """On the first pass (no trial): the component's end force against this pass's force at the end state,
        F* - F_law(e*, v*; phi_n + omega_m (t* - t_n)) - c_n = c* - c_n, what a second pass would ramp in (the
        master's ``_next_pass_negligible`` predicts its effect); None on later passes, without a law, or when a
        contact onset in this pass's substeps needs its correction (``_onset_corrections``: a second pass)."""
        if self.law is None or self.trial is not None or self._onset_corrections(self._m, self._bounds, b):
            return None
        out = self._evaluate(b.e_x, b.e_y, b.v_x, b.v_y, self._cage + self._omega * (b.t - self._t_n), self._wi,
                             self._wo)
        return b.F_x - (float(out[0]) + self._c0[0]), b.F_y - (float(out[1]) + self._c0[1])


def onset_fraction(da: float, db: float, ma: float, mb: float) -> float:
    """The root theta in (0, 1] of the cubic Hermite interpolant through (da, ma) at sigma = 0 and (db, mb) at
    sigma = 1 (a ball's deflection and its rate per substep, da <= 0 < db): Newton from the linear root, kept while
    it stays in (0, 1] with a positive slope (four steps)."""
    theta = da / (da - db)
    for _ in range(4):
        t2 = theta * theta
        t3 = t2 * theta
        p = (2.0 * t3 - 3.0 * t2 + 1.0) * da + (t3 - 2.0 * t2 + theta) * ma + (3.0 * t2 - 2.0 * t3) * db \
            + (t3 - t2) * mb
        dp = (6.0 * t2 - 6.0 * theta) * (da - db) + (3.0 * t2 - 4.0 * theta + 1.0) * ma + (3.0 * t2 - 2.0 * theta) * mb
        if not dp > 0.0:
            break
        nxt = theta - p / dp
        if not 0.0 < nxt <= 1.0:
            break
        theta = nxt
    return theta


def onset_weights(theta: float, j: float, d: float) -> tuple[float, float]:
    """(g0, g1) [N]: the force g0 + g1 sigma over a substep that RK4 integrates exactly and that makes up RK4's
    velocity and position deficits for a force switched on at sigma = theta with the value j, growing by d per
    substep (eq. 18's damping jump at a contact onset; ``LawModel._onset_corrections``).

    Exact: impulse h (j r + d r^2 / 2), first moment h^2 (j r^2 / 2 + d r^3 / 6), r = 1 - theta. RK4's, from its
    stage values f_0 = 0, f_1 = f_2 = f_m = [theta < 1/2] (j + d (1/2 - theta)), f_3 = j + d r: h (4 f_m + f_3) / 6
    and h^2 f_m / 3. g0 + g1 sigma adds h (g0 + g1 / 2) and h^2 (g0 / 2 + g1 / 6)."""
    half = 1.0 if theta < 0.5 else 0.0
    r = 1.0 - theta
    fm = half * (j + d * (0.5 - theta))
    f1 = j + d * r
    a = j * r + d * r * r / 2.0 - (4.0 * fm + f1) / 6.0
    b = j * r * r / 2.0 + d * r * r * r / 6.0 - fm / 3.0
    return 6.0 * b - 2.0 * a, 6.0 * a - 12.0 * b
