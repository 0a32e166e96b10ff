"""Polynomial extrapolation of the exchanged force: linear (``extrap1``) and quadratic (``extrap2``)."""
from __future__ import annotations

from .base import ForceModel, Scheme


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

    def force_model(self, t0, h):
        x1 = self.past[-1]
        if len(self.past) < 2:
            return ForceModel(x1.t, (x1.F_x, x1.F_y))
        x0 = self.past[-2]
        dt = x1.t - x0.t
        return ForceModel(x1.t, (x1.F_x, x1.F_y), ((x1.F_x - x0.F_x) / dt, (x1.F_y - x0.F_y) / dt))


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

    def force_model(self, t0, h):
        if len(self.past) < 3:
            return LinearExtrapolation.force_model(self, t0, h)
        a, b, c = self.past
        # Newton form about t_c: F_c + f[c,b] s + f[c,b,a] s (s + t_c - t_b), s = tau - t_c
        cbx, cby = (c.F_x - b.F_x) / (c.t - b.t), (c.F_y - b.F_y) / (c.t - b.t)
        bax, bay = (b.F_x - a.F_x) / (b.t - a.t), (b.F_y - a.F_y) / (b.t - a.t)
        qx, qy = (cbx - bax) / (c.t - a.t), (cby - bay) / (c.t - a.t)
        w = c.t - b.t
        return ForceModel(c.t, (c.F_x, c.F_y), (cbx + qx * w, cby + qy * w), (qx, qy))
