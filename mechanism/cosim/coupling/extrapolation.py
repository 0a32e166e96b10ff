"""Polynomial extrapolation of the exchanged force: linear (``extrap1``) and quadratic (``extrap2``)."""
from __future__ import annotations

from .base import Scheme


class LinearExtrapolation(Scheme):
    """F(tau) = F_n + (F_n - F_{n-1}) (tau - t_n) / (t_n - t_{n-1}); ZOH on the first step."""

    name = "extrap1"
    history = 2

    def force(self, tau, e_x, e_y, v_x, v_y):
        x1 = self.past[-1]
        if len(self.past) < 2:
            return x1.F_x, x1.F_y
        x0 = self.past[-2]
        s = (tau - x1.t) / (x1.t - x0.t)
        return x1.F_x + s * (x1.F_x - x0.F_x), x1.F_y + s * (x1.F_y - x0.F_y)


class QuadraticExtrapolation(Scheme):
    """Lagrange quadratic through the last three exchanged forces; lower order until they exist."""

    name = "extrap2"
    history = 3

    def force(self, tau, e_x, e_y, v_x, v_y):
        if len(self.past) < 3:
            return LinearExtrapolation.force(self, tau, e_x, e_y, v_x, v_y)
        a, b, c = self.past
        la = (tau - b.t) * (tau - c.t) / ((a.t - b.t) * (a.t - c.t))
        lb = (tau - a.t) * (tau - c.t) / ((b.t - a.t) * (b.t - c.t))
        lc = (tau - a.t) * (tau - b.t) / ((c.t - a.t) * (c.t - b.t))
        return la * a.F_x + lb * b.F_x + lc * c.F_x, la * a.F_y + lb * b.F_y + lc * c.F_y
