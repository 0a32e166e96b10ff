"""Interface-Jacobian schemes: the component's tangent stiffness and damping close the loop within a step.

``jacobian``: F = F_n + K_n (e - e_n) + C_n (v - v_n); ``jacobian-drift`` adds the extrapolated drift of
the force that K and C do not explain.
"""
from __future__ import annotations

from .base import Exchanged, ForceModel, Scheme


class InterfaceJacobian(Scheme):
    """F(tau) = F_n + K_n (e - e_n) + C_n (v - v_n): the component's tangent matrices close the loop."""

    name = "jacobian"
    uses_tangent = True

    def force(self, tau, e_x, e_y, v_x, v_y):
        return _linear(self.past[-1], e_x, e_y, v_x, v_y)

    def force_model(self, t0, h):
        return ForceModel.linear(self.past[-1])


def _linear(x: Exchanged, e_x: float, e_y: float, v_x: float, v_y: float) -> tuple[float, float]:
    """F_x + K (e - e_x) + C (v - v_x): the exchanged force continued along its tangent matrices."""
    dx, dy, dvx, dvy = e_x - x.e_x, e_y - x.e_y, v_x - x.v_x, v_y - x.v_y
    return (x.F_x + x.k_xx * dx + x.k_xy * dy + x.c_xx * dvx + x.c_xy * dvy,
            x.F_y + x.k_xy * dx + x.k_yy * dy + x.c_xy * dvx + x.c_yy * dvy)


class InterfaceJacobianDrift(InterfaceJacobian):
    """``jacobian`` plus the extrapolated drift d_n (tau - t_n) of the force not explained by K and C."""

    name = "jacobian-drift"
    history = 2

    def begin_step(self, t: float, h: float) -> None:
        super().begin_step(t, h)
        self._drift = (0.0, 0.0)
        if len(self.past) == 2:
            a, b = self.past
            predicted = _linear(a, b.e_x, b.e_y, b.v_x, b.v_y)
            dt = b.t - a.t
            self._drift = ((b.F_x - predicted[0]) / dt, (b.F_y - predicted[1]) / dt)

    def force(self, tau, e_x, e_y, v_x, v_y):
        fx, fy = _linear(self.past[-1], e_x, e_y, v_x, v_y)
        s = tau - self.past[-1].t
        return fx + self._drift[0] * s, fy + self._drift[1] * s

    def force_model(self, t0, h):
        return ForceModel.linear(self.past[-1], self._drift)
