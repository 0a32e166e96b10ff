"""Zero-order hold of the exchanged force: Gauss-Seidel (``zoh``) and Jacobi (``zoh-jacobi``) ordering; 1st order."""
from __future__ import annotations

from .base import ForceModel, Scheme


class ZeroOrderHold(Scheme):
    """F(tau) = F_n (Gauss-Seidel: F_n is the force for the state at t_n)."""

    name = "zoh"

    def force(self, tau, e_x, e_y, v_x, v_y):
        x = self.past[-1]
        return x.F_x, x.F_y

    def force_model(self, t0, h):
        x = self.past[-1]
        return ForceModel(x.t, (x.F_x, x.F_y))


class ZeroOrderHoldJacobi(ZeroOrderHold):
    """F(tau) = F_n, where the component stepped in parallel with inputs from t_{n-1} (Jacobi)."""

    name = "zoh-jacobi"
    ordering = "jacobi"
