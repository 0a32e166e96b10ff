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
ramp to the last pass's c*; ``converged`` compares two passes' end-of-step force and eccentricity. The ring
speeds sent to the component are the secant ones (implicit.py). The master's RK4 substeps are sized by the
stiffest law tangent met in the step, ``resolution`` times finer than stability needs (``substep_tangent``),
and from the second pass each contact onset gets a constant correction over its substep that makes RK4's
impulse of the damping jump exact (``_onset_corrections``). docs/coupling.md, "Model-based coupling".

Needs the law (``bind_law``, from the master's ``contact_law``) and, each step, the cage angle and ring
speeds at t_n (``set_cage``) and the substeps (``set_substeps``); without a law it is ``jacobian-implicit``.
"""
from __future__ import annotations

import math

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import DAMPING_CONSTANT

from .base import Exchanged
from .implicit import InterfaceJacobianImplicit


class LawModel(InterfaceJacobianImplicit):
    """The component's force law plus the exchanged correction as the force within a step (iterated)."""

    name = "law-model"
    uses_law = True
    #: substeps per communication step, relative to those RK4's stability needs (``substep_tangent``)
    resolution = 8.0
    #: False: no onset correction (``_onset_corrections``; for measurements)
    onset_correction = True

    def __init__(self):
        super().__init__()
        self.law: BallBearing | None = None
        self._evaluate = None
        self._cage = 0.0             # phi_n [rad]
        self._omega = 0.0            # omega_m [rad/s] (eq. 16 at t_n)
        self._wi = self._wo = 0.0    # ring speeds at t_n [rad/s] (the oil-film law's entrainment speed)
        self._h_step = 1.0
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
        k = _eig_max(out[2], out[3], out[4])
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
            self._k_seen, self._tangent = _eig_max(a.k_xx, a.k_xy, a.k_yy), (a.k_xx, a.k_xy, a.k_yy,
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
        self._h_step = h
        if self.trial is None:
            self._recorded = None
        elif self._bounds:
            self._recorded = (self._m, self._bounds)
        self._bounds, self._onsets, self._calls = {}, {}, 0

    def set_substeps(self, m: int) -> None:
        """The master's RK4 substeps in the coming pass. From the second pass on, each ball's contact onset in a
        substep of the last pass (same substeps) gets the onset correction of that substep (``_onset_corrections``)."""
        self._m = m
        if self.onset_correction and self._recorded is not None and self._recorded[0] == m and self.trial is not None:
            self._onsets = self._onset_corrections(m, self._recorded[1], self.trial)

    def _onset_corrections(self, m: int, bounds: dict, end: Exchanged) -> dict[int, tuple[float, float]]:
        """Per substep, the constant force that makes RK4's impulse of each damping jump exact.

        A ball entering the load zone at t_k + theta h_s switches its damping force J = C max(v_r, 0) u_r on at
        once (eq. 18, as ``implicit.onset_jumps``). RK4 samples it at its stages s = 0, h_s/2 (twice), h_s with
        weights 1/6, 1/3, 1/3, 1/6: the impulse J h_s (1/6 + 2/3 [theta < 1/2]) instead of J h_s (1 - theta), an
        O(h_s) error per onset (first order). A constant g over the substep is integrated exactly; g = J [(1 -
        theta) - 1/6 - 2/3 [theta < 1/2]] gives the exact impulse. theta from the linear interpolation of
        delta_r = e . u_r - P_d/2 between the substep's ends (of the last pass; the end of the step is ``end``)."""
        law = self.law
        if law.damping_model != DAMPING_CONSTANT or law.damping_coefficient == 0.0:
            return {}
        C, half, hs = law.damping_coefficient, law.half_clearance, self._h_step / m
        points = dict(bounds)
        points[m] = (end.e_x, end.e_y, end.v_x, end.v_y)
        spacing = 2.0 * math.pi / law.n_balls
        out = {}
        for k in range(m):
            a, b = points.get(k), points.get(k + 1)
            if a is None or b is None:
                continue
            pa, pb = self._cage + self._omega * k * hs, self._cage + self._omega * (k + 1) * hs
            gx = gy = 0.0
            for r in range(law.n_balls):
                ca, sa = math.cos(pa + r * spacing), math.sin(pa + r * spacing)
                cb, sb = math.cos(pb + r * spacing), math.sin(pb + r * spacing)
                da, db = a[0] * ca + a[1] * sa - half, b[0] * cb + b[1] * sb - half
                if not da <= 0.0 < db:
                    continue
                theta = da / (da - db)
                phi = pa + r * spacing + theta * (pb - pa)
                ux, uy = math.cos(phi), math.sin(phi)
                vr = (a[2] + theta * (b[2] - a[2])) * ux + (a[3] + theta * (b[3] - a[3])) * uy
                w = (1.0 - theta) - (1.0 / 6.0 + (2.0 / 3.0 if theta < 0.5 else 0.0))
                g = C * max(vr, 0.0) * w
                gx, gy = gx + g * ux, gy + g * uy
            if gx or gy:
                out[k] = (gx, gy)
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
            fx, fy = fx + g[0], fy + g[1]
        r = s / self._h_step
        return (fx + self._c0[0] + r * (self._c1[0] - self._c0[0]),
                fy + self._c0[1] + r * (self._c1[1] - self._c0[1]))

    def force_model(self, t0, h):
        return self._model if self.law is None else None


def _eig_max(a: float, b: float, c: float) -> float:
    """Largest eigenvalue of the symmetric 2x2 matrix [[a, b], [b, c]]."""
    return 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)
