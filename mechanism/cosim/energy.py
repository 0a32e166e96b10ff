"""The energy account of a run: where the mechanism's energy went, and what the coupling created.

Along the mechanism's trajectory (whatever force it felt), the bearing's force law
(``fmu_bearing.ball_bearing.BallBearing``, the one home of eq. 18-19) says:

* contact potential energy   V = sum_r (2/5) K delta_r^(5/2)  (the integral of F . d delta of the
  Hertz law, ``BallBearing.elastic_energy``);
* damping dissipation        D = int (F - F_el) . v dt >= 0, where F is the law's force and F_el the
  same law at v = 0 (the elastic part, clamped contacts included: a ball whose damping would pull
  carries 0 N, its elastic power is dissipated);
* cage work                  W_cage = int omega_m (F_el x e)_z dt: the cage (eq. 16) carries the loaded
  balls round under a fixed e, changing V at fixed e; the model's frictionless balls take this
  energy from, or give it to, the kinematic cage (dV/dt = F_el . v + omega_m (F_el x e)_z);
* work of the driving moment W_drive = int lambda . Phi_t dt (the power of the rheonomic constraints,
  here the crank driver: M omega), plus the work of the applied forces W_applied = int Q^A . q' dt.

The mechanism's energy balance, exact for the monolithic model, is then

    T + V + D - W_drive - W_applied - W_cage = T_0 + V_0,

and its **residual** R = T + V + D - W_drive - W_applied - W_cage - T_0 - V_0 is the energy the coupling
created (R > 0) or destroyed (R < 0), up to the error of the integrals, which is why they are computed
inside the integrators, not from the samples (issue 12):

* the monolithic reference (``monolithic.py``) carries D, W_drive, W_cage, W_applied as ODE states, under its
  integrator's error control, the contact onsets located as events: R is its integrator's error
  (|R| / D 1e-5 ... 2e-4 over two revolutions with 8 balls, 1.4e-3 with 15/20 balls at rtol 1e-9, 3e-6 at
  rtol 1e-10; tests/test_energy.py);
* the co-simulation master (``master.CouplingLoop``) integrates the powers with its RK4 stages, the quadrature
  RK4 applies to a state whose derivative they are: the mechanism's powers (drivers, applied, and the bearing
  force's work on the mechanism W_link) in the step itself (``kernels.advance``, or the NumPy path), the law's
  damping and cage powers at the recorded stage states with each contact onset located in its substep
  (``energy_kernel.stage_integrals``); ``update(..., integrals=...)`` then takes them as they are. The
  mechanism's own balance T - T_0 = W_drive + W_applied + W_link closes to the RK4 error, so R is the
  interface's W_link + V - V_0 + D - W_cage: the bearing force the mechanism felt against what the law
  stores and dissipates along the same motion (meta ``energy_residual_mechanism_J`` and
  ``energy_residual_coupling_J``).

Without ``integrals`` (``monolithic`` with ``energy_states=False``) the integrals are quadratures of the samples
(2-step Adams-Moulton rule, trapezoidal where the spacing changes): at 1e-5 s sampling its error was 6 % of D
for the reference and +8 mJ (against D = 4.4 mJ) for the co-simulation's start-up, where the multipliers at
the samples miss the force the mechanism felt within the steps (docs/coupling.md).

The cage angle used is the kinematic one, cage_0 + omega_m(Delta theta_journal, Delta theta_housing)
(eq. 16 is linear in the ring speeds, so its time integral is the same combination of the ring
angles): the law's truth along the trajectory, independent of how the component integrated it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from fmu_bearing.ball_bearing import BallBearing
from mechanism.cosim.joint import BearingLink
from mechanism.multibody.solver import System

#: CSV columns of the account [J], in order
ENERGY_COLUMNS = ("contact_energy", "damping_dissipation", "drive_work", "cage_work", "applied_work",
                  "energy_residual")


def account_powers(system: System, bearing: BallBearing, t: float, q: np.ndarray, qd: np.ndarray, lam: np.ndarray,
                   inputs: Sequence[float], force: Sequence[float], elastic: Sequence[float]
                   ) -> tuple[float, float, float, float]:
    """The time derivatives of the account's integrals [W] at one state, in the order of ``_sums``:
    damping (F - F_el) . v, drivers lambda . Phi_t, cage omega_m (F_el x e)_z, applied Q^A . q'.

    ``inputs`` = (e_x, e_y, v_x, v_y, omega_inner, omega_outer) of the link at (q, q'), ``force`` = (F_x, F_y) of
    the law there and ``elastic`` the law at v = 0. The one home of the account's powers: the sampled account
    (``EnergyAccount.update``) and the monolithic reference's quadrature states (``monolithic.py``) use it."""
    ex, ey, vx, vy, wi, wo = inputs
    fx, fy = force
    el_x, el_y = elastic
    return ((fx - el_x) * vx + (fy - el_y) * vy,
            float(np.dot(lam, system.phi_t(t))) if system.m else 0.0,
            bearing.cage_velocity(wi, wo) * (el_x * ey - el_y * ex),
            float(np.dot(system.applied_forces(q, qd, t), qd)))


def kinematic_cage_angle(bearing: BallBearing, link: BearingLink, angles0: tuple[float, float],
                         q: np.ndarray) -> float:
    """The kinematic cage angle [rad] at q: cage_0 plus eq. (16) applied to the changes of the ring angles
    since ``angles0`` (``link.ring_angles`` at the start). Used by the energy account and by the master to
    locate contact onsets (``coupling.implicit.onset_jumps``), with or without an account."""
    aj, ai = link.ring_angles(q)
    return float(bearing.params.cage_angle_start + bearing.cage_velocity(aj - angles0[0], ai - angles0[1]))


@dataclass
class EnergyAccount:
    """Running energy account, updated at every sample (``update``) with the trapezoidal rule."""

    system: System
    link: BearingLink
    bearing: BallBearing
    _last: tuple | None = field(default=None, init=False)
    _before: tuple | None = field(default=None, init=False)
    _sums: list = field(default_factory=lambda: [0.0, 0.0, 0.0, 0.0], init=False)   # D, W_drive, W_cage, W_app
    _start: float = field(default=0.0, init=False)
    _angles0: tuple = field(default=(0.0, 0.0), init=False)
    _kernel: object = field(default=None, init=False)     # the compiled law, or False without numba
    _stage_kernel: object = field(default=None, init=False)

    def cage_angle(self, q: np.ndarray) -> float:
        """The kinematic cage angle [rad]: cage_0 plus eq. (16) applied to the ring angles' changes."""
        return kinematic_cage_angle(self.bearing, self.link, self._angles0, q)

    def _potential(self, ex, ey, cage) -> float:
        """The contact energy V [J] at (e, cage angle), compiled (``law_kernel.elastic_energy``) when numba is there."""
        if self._kernel is None:
            self._forces(ex, ey, 0.0, 0.0, cage, 0.0, 0.0)           # sets up the compiled law (or False)
        if self._kernel:
            return float(self._kernel[1](self._kernel[2], ex, ey, cage))
        return self.bearing.elastic_energy(ex, ey, cage)

    def _forces(self, ex, ey, vx, vy, cage, wi, wo) -> tuple[float, float, float, float, float]:
        """(F_x, F_y) of the law, (F_x, F_y) at v = 0 (the elastic part) and the contact energy V [J],
        through the compiled law (``law_kernel``, held to 1e-12 against ``BallBearing``) when numba is there."""
        if self._kernel is None:
            try:
                from mechanism.cosim import law_kernel
                self._kernel = (law_kernel.evaluate, law_kernel.elastic_energy, law_kernel.pack_bearing(self.bearing),
                                np.zeros(10), np.zeros(self.bearing.n_balls))
            except ImportError:
                self._kernel = False
        if self._kernel:
            evaluate, energy, P, out, loads = self._kernel
            evaluate(P, ex, ey, vx, vy, cage, wi, wo, out, loads)
            fx, fy = float(out[0]), float(out[1])
            evaluate(P, ex, ey, 0.0, 0.0, cage, wi, wo, out, loads)
            return fx, fy, float(out[0]), float(out[1]), energy(P, ex, ey, cage)
        law = self.bearing.evaluate(ex, ey, vx, vy, cage, wi, wo)
        elastic = self.bearing.evaluate(ex, ey, 0.0, 0.0, cage, wi, wo)
        return law.F_x, law.F_y, elastic.F_x, elastic.F_y, self.bearing.elastic_energy(ex, ey, cage)

    def stage_integrals(self, stages: np.ndarray, substeps: int, hs: float) -> tuple[float, float]:
        """(D, W_cage) [J] over one integrator step from its stage states (``energy_kernel.stage_integrals``);
        after the first ``update`` (which fixes the ring angles the kinematic cage angle starts from)."""
        if self._stage_kernel is None:
            from mechanism.cosim import energy_kernel, law_kernel
            b = self.bearing
            offset = (b.params.cage_angle_start - b.cage_velocity(self._angles0[0], self._angles0[1]))
            self._stage_kernel = (energy_kernel.stage_integrals, law_kernel.pack_bearing(b), offset)
        kernel, P, offset = self._stage_kernel
        return kernel(P, stages, substeps, hs, offset)

    def update(self, t: float, q: np.ndarray, qd: np.ndarray, lam: np.ndarray, inputs: Sequence[float] | None = None,
               kinetic: float | None = None, integrals: Sequence[float] | None = None) -> dict[str, float]:
        """Account up to time t [s] for the state (q, qd) and the multipliers lam of eq. (9) (model order).

        ``inputs`` (the link's (e, v, omega) at (q, qd)) and ``kinetic`` (T at qd) when the caller has them.
        ``integrals``: (D, W_drive, W_cage, W_applied) [J] since the start, integrated by the caller's integrator
        (the co-simulation master's RK4 stages, ``CouplingLoop``): used as they are; without them the
        integrals are quadratures of the samples (2-step Adams-Moulton)."""
        if self._last is None:
            self._angles0 = self.link.ring_angles(q)
        ex, ey, vx, vy, wi, wo = self.link.inputs(q, qd) if inputs is None else inputs
        cage = self.cage_angle(q)
        system = self.system
        if integrals is not None and self._last is not None:      # only V is needed at the sample
            powers = None
            potential = self._potential(ex, ey, cage)
        else:
            fx, fy, el_x, el_y, potential = self._forces(ex, ey, vx, vy, cage, wi, wo)
            powers = account_powers(system, self.bearing, t, q, qd, lam, (ex, ey, vx, vy, wi, wo), (fx, fy),
                                    (el_x, el_y))
        if kinetic is None:
            kinetic = system.kinetic_energy(qd)
        if self._last is None:
            self._start = kinetic + potential
        elif integrals is not None:
            self._sums[:] = [float(v) for v in integrals[:4]]
        else:
            t1, p1 = self._last
            dt = t - t1
            if self._before is not None and abs((t1 - self._before[0]) - dt) <= 1e-9 * dt:
                p0 = self._before[1]             # equal spacing: the 2-step Adams-Moulton rule, O(dt^3)
                for k in range(4):
                    self._sums[k] += dt / 12.0 * (5.0 * powers[k] + 8.0 * p1[k] - p0[k])
            else:                                # first interval or a change of spacing: trapezoidal rule
                for k in range(4):
                    self._sums[k] += 0.5 * dt * (p1[k] + powers[k])
        self._before, self._last = self._last, (t, powers)
        dissipated, drive, cage_work, applied = self._sums
        return {"contact_energy": potential, "damping_dissipation": dissipated, "drive_work": drive,
                "cage_work": cage_work, "applied_work": applied,
                "energy_residual": kinetic + potential + dissipated - drive - applied - cage_work - self._start}

