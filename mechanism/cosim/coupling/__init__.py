"""Coupling schemes: what force the mechanism sees from the bearing during a communication step.

Notation: communication points t_n, step h; the bearing component returns at t_n its force
F_n (on the housing) and, where it provides them, its tangent stiffness K_n = dF/de and
damping C_n = dF/dv at the inputs e_n, v_n it was given. Within [t_n, t_n + h] the master
integrates the mechanism with a force model F(tau, e, v) chosen by the scheme:

============  =====================================================  ==========  ===============
name          force on the mechanism over the step                   ordering    accuracy
============  =====================================================  ==========  ===============
zoh-jacobi    F_n held, where F_n = F(e_{n-1}) (both sides step in   Jacobi      1st order
              parallel from the values at t_{n-1})
zoh           F_n held (zero-order hold), F_n = F(e_n)               Gauss-Seidel 1st order
extrap1       F_n + (F_n - F_{n-1}) (tau - t_n) / h  (linear)        Gauss-Seidel 2nd order
extrap2       quadratic through F_{n-2}, F_{n-1}, F_n                Gauss-Seidel 3rd order
jacobian      F_n + K_n (e(tau) - e_n) + C_n (v(tau) - v_n)          Gauss-Seidel 2nd order
              (interface-Jacobian, linearly implicit coupling)
jacobian-     jacobian + d_n (tau - t_n), where d_n is the drift of  Gauss-Seidel 2nd order
drift         the last step not explained by K and C:                             (smaller
(default)     d_n = [F_n - F_{n-1} - K_{n-1} (e_n - e_{n-1})                     constant)
                     - C_{n-1} (v_n - v_{n-1})] / (t_n - t_{n-1})
jacobian-     jacobian-drift, the component given the secant ring   Gauss-Seidel nominal 2nd
secant        speeds (theta_{n+1} - theta_n)/h: its cage angle exact              (implicit.py)
jacobian-     the step repeated with rollback (FMU get/set state):  Gauss-Seidel nominal 2nd
implicit      K, C the mean of both ends, d the drift of this step  iterated
              through F_{n+1} of the last pass (implicit.py)
law-model     the component's force law (eq. 18-19, known to the     Gauss-Seidel the master's RK4
              master) within the step, plus the exchanged            iterated     substeps'
              corrections F - F_law at both ends (law_model.py;
              without a law: jacobian-implicit)
============  =====================================================  ==========  ===============

"accuracy" is the nominal order for a smooth force; the measured orders are lower (the damping
jump at each contact onset), see docs/coupling.md.

Gauss-Seidel ordering: the mechanism steps first; then the bearing is given the new inputs
u_{n+1} and steps, so that F_{n+1} is the force at t_{n+1} for the state at t_{n+1}.
Jacobi ordering: the bearing steps with the inputs u_n while the mechanism steps with the
previous force; the force the mechanism sees lags one step behind.

Why ``jacobian`` is the default: holding or extrapolating the contact force of a stiff,
lightly damped contact injects energy every step (the force lags the motion), so those
schemes need steps far below the contact period (about 0.5 ms here). Feeding the
component's own tangent matrices back into the mechanism's step makes the coupling
linearly implicit: the mechanism feels the contact's stiffness and damping within the step,
and the step is limited by accuracy, not by the coupling's stability. What K and C do not
explain is mostly the cage turning the balls under a fixed eccentricity (balls entering and
leaving the load zone); ``jacobian-drift`` extrapolates that part from the last step, which
cut the error of the rev-2 peaks at 1200 rpm and h = 1e-5 s from 0.5 % to 0.06 %. The master subcycles
its own integration where the tangent stiffness requires it (see ``master.substeps``), at
no extra exchange with the component. See docs/coupling.md for the equations and measurements.
"""
from __future__ import annotations

from .base import Exchanged, ForceModel, Scheme
from .extrapolation import LinearExtrapolation, QuadraticExtrapolation
from .hold import ZeroOrderHold, ZeroOrderHoldJacobi
from .implicit import InterfaceJacobianImplicit, InterfaceJacobianSecant
from .jacobian import InterfaceJacobian, InterfaceJacobianDrift
from .law_model import LawModel

SCHEMES: dict[str, type[Scheme]] = {cls.name: cls for cls in (
    InterfaceJacobianDrift, InterfaceJacobian, InterfaceJacobianSecant, InterfaceJacobianImplicit,
    ZeroOrderHold, ZeroOrderHoldJacobi, LinearExtrapolation,
    QuadraticExtrapolation, LawModel)}
#: the default scheme (docs/coupling.md, "The default scheme"): third order in the step, stable and within 1 %
#: at 1e-4 s; without a known law (the journal-clearance component) it is jacobian-implicit
DEFAULT_SCHEME = LawModel.name


def make_scheme(name: str) -> Scheme:
    try:
        return SCHEMES[name]()
    except KeyError:
        raise ValueError(f"unknown coupling scheme {name!r}; choose from {', '.join(SCHEMES)}") from None


__all__ = ["DEFAULT_SCHEME", "SCHEMES", "Exchanged", "ForceModel", "InterfaceJacobian", "InterfaceJacobianDrift",
           "InterfaceJacobianImplicit", "InterfaceJacobianSecant", "LawModel",
           "LinearExtrapolation", "QuadraticExtrapolation", "Scheme", "ZeroOrderHold", "ZeroOrderHoldJacobi",
           "make_scheme"]
