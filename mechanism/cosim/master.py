"""The co-simulation master: integrates the mechanism and exchanges signals with the bearing each step.

One loop serves every run: the bearing component is an *endpoint* (the FMU through fmpy,
or the same force law in-process, ``mechanism.cosim.endpoints``) and the coupling *scheme*
(``mechanism.cosim.coupling``) says what force the mechanism sees within a step. With no
bearing (the ideal joint) the same loop integrates the constrained mechanism alone.

Each communication step [t_n, t_n + h]:
1. (Jacobi ordering only) the component steps with the inputs u_n;
2. the mechanism is integrated with RK4 in ``substeps`` equal substeps, the bearing force
   given by the scheme's force model, applied through eq. (20)-(23);
3. (Gauss-Seidel ordering) the component is given u_{n+1} (eq. 10-12 and the ring speeds)
   and steps; its outputs F_{n+1} (and tangent matrices) are pushed to the scheme;
4. at the output interval a sample is recorded: the end-of-step state, the force, the
   accelerations and Lagrange multipliers of eq. (9) with that force (slider acceleration,
   crank moment), and the component's sampled outputs (ball loads, cage angle, ...).

A failure (an error status from the component, a non-finite state, constraints drifting
beyond ``max_constraint_violation``) stops the run with a message naming the step, the
time and the cause; the samples recorded so far are kept and the component is always freed.

An iterative scheme (``law-model``, the default, or ``jacobian-implicit``) repeats steps 2-3 with rollback until the
end-of-step exchange converges (``CouplingLoop.communicate``; the component's state is restored by
its get/set FMU state). An energy account (``mechanism.cosim.energy``), if given, adds its columns
to every sample.

The step itself (1-3) and the sample (4) live in ``CouplingLoop``, shared with the adaptive
driver (``mechanism.cosim.adaptive``), which also uses its ``snapshot``/``restore`` to roll back.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Callable, Protocol, Sequence

import numpy as np

from mechanism.cosim.coupling import DEFAULT_SCHEME, Exchanged, make_scheme
from mechanism.cosim.coupling.base import FORCE_MODEL_FIELDS, sym_eig_max
from mechanism.cosim.coupling.implicit import onset_jumps
from mechanism.cosim.energy import ENERGY_COLUMNS, EnergyAccount, kinematic_cage_angle
from mechanism.cosim.joint import BearingLink
from mechanism.cosim.record import BASE_COLUMNS, Recorder, RunResult
from mechanism.multibody.integrators import rk4_step
from mechanism.multibody.solver import System


class Endpoint(Protocol):
    sample_names: Sequence[str]
    calls: int

    def initialize(self, inputs: Sequence[float]) -> tuple[float, ...]: ...
    def exchange(self, t: float, h: float, inputs: Sequence[float]) -> tuple[float, ...]: ...
    def sample(self) -> list[float]: ...
    def close(self) -> None: ...


class RunFailure(RuntimeError):
    """A run stopped early; ``step`` and ``time`` say where."""

    def __init__(self, step: int, time: float, cause: str):
        super().__init__(f"stopped at step {step} (t = {time:.9g} s): {cause}")
        self.step, self.time, self.cause = step, time, cause


@dataclass
class MasterSettings:
    """Fixed-step master settings (SI)."""

    t_end: float
    step: float = 1e-5                   # communication step h [s]
    output_interval: float = 1e-5        # sampling interval, rounded to a multiple of h [s]
    scheme: str = DEFAULT_SCHEME
    substep_limit: float = 1.0           # substeps keep h_sub * (omega_contact + damping rate) <= this
    max_substeps: int = 64
    max_constraint_violation: float = 1e-4   # |Phi| beyond this [m or rad] is divergence
    progress: bool = True
    description: str = "co-simulation"
    max_iterations: int = 8              # iterated schemes: passes per step at most (then accepted, counted)
    iteration_tol: float = 1e-7          # iterated schemes: end force / eccentricity agreement (relative)
    kernels: bool = True                 # compiled step (mechanism.multibody.kernels); False: the NumPy reference
    iterate_where_needed: bool = True    # iterated schemes: also stop when the predicted change of a further pass is
                                         # within iteration_tol (CouplingLoop._next_pass_negligible); False: always
                                         # repeat until two passes agree
    compiled_loop: bool = True           # the whole step compiled (mechanism.cosim.compiled_driver) where it applies
                                         # (in-process component or FMI 2.0 FMU, interface-Jacobian schemes); False:
                                         # the Python loop


#: observe(q, qd, qdd, lam, t) -> named observables of the mechanism (slider_x, crank_moment, ...)
Observer = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float], dict]


def substeps(h: float, x: Exchanged, mobility: float, limit: float, cap: int) -> int:
    """RK4 substeps per communication step for the interface-Jacobian force model.

    The tangent stiffness k and damping c (largest eigenvalues) acting on the mechanism's
    relative mobility g give a contact frequency sqrt(k g) and a damping rate c g; RK4 is
    stable up to about 2.8 in h_sub times either, so ``limit`` = 1 keeps a wide margin.
    """
    k = max(sym_eig_max(x.k_xx, x.k_xy, x.k_yy), 0.0)
    c = max(sym_eig_max(x.c_xx, x.c_xy, x.c_yy), 0.0)
    rate = math.sqrt(k * mobility) + c * mobility
    return max(1, min(cap, math.ceil(h * rate / limit)))


class CouplingLoop:
    """The pieces of one co-simulation run, shared by ``run_master`` and ``mechanism.cosim.adaptive``.

    It owns the coupling scheme, the exchanged inputs and force, and the substep counters;
    ``start`` initialises the component, ``advance`` performs one communication step
    (steps 1-3 of the module docstring) and ``row`` builds a sample (step 4). ``snapshot``
    and ``restore`` save and roll back everything a step changes besides the mechanism's
    state y: the scheme's history, the last exchange, and the component's state (through
    the endpoint's ``get_state``/``set_state``, i.e. the FMU's get/set FMU state).
    """

    def __init__(self, system: System, settings: MasterSettings, observe: Observer,
                 link: BearingLink | None = None, endpoint: Endpoint | None = None,
                 reaction_force: Callable[[np.ndarray, np.ndarray], tuple[float, float]] | None = None,
                 energy: EnergyAccount | None = None, contact_law=None):
        self.system, self.settings, self.observe = system, settings, observe
        self.energy = energy
        #: the ball-bearing law (``BallBearing``) an iterative scheme locates contact onsets with
        #: (``onset_jumps``): ``contact_law``, else the energy account's, else the in-process endpoint's.
        #: Part of the physics: never depends on whether an energy account is recorded.
        if contact_law is None and energy is not None:
            contact_law = energy.bearing
        if contact_law is None:
            contact_law = getattr(endpoint, "bearing", None)
        self.contact_law = contact_law if link is not None else None
        self._angles0 = (0.0, 0.0)
        self.link, self.endpoint, self.reaction_force = link, endpoint, reaction_force
        self.sample_names = list(endpoint.sample_names) if endpoint is not None else []
        # a step whose end is sampled may fetch the samples with the coupling outputs (FmuEndpoint)
        self._exchange_sampled = (getattr(endpoint, "exchange_sampled", None) or endpoint.exchange
                                  if endpoint is not None and self.sample_names else None)
        self.columns = list(BASE_COLUMNS) + [c for c in self.sample_names if c not in BASE_COLUMNS]
        if energy is not None:
            self.columns += list(ENERGY_COLUMNS)
        self.n = system.n
        self.scheme = make_scheme(settings.scheme) if endpoint is not None else None
        #: the energy account's integrals since the start [J], integrated with the RK4 stages of every accepted
        #: step (``_integrate_energy``): D, W_drive, W_cage, W_applied, and the work of the bearing force on the
        #: mechanism (W_link); rolled back with the step (``snapshot``/``restore``)
        self.integrals = np.zeros(5) if energy is not None and link is not None else None
        # also without an account: the kernels always get these arrays (one compiled specialisation of
        # kernels.advance and finish, not a second one for the omitted arguments); unused then
        self._acc = np.zeros(3)                                       # W_drive, W_applied, W_link of one step
        self._p1 = np.zeros(3)                                        # the powers at the end state (next k1)
        self._stages = np.zeros((5 * max(1, settings.max_substeps), 8))
        self.inputs = None
        self.force = (0.0, 0.0)
        self.mobility = 0.0
        self.substeps_max = 1
        self.substeps_total = 0
        self.iterations = {"steps": 0, "passes": 0, "max_passes": 0, "not_converged": 0, "predicted": 0}
        #: ring speeds sent with the last exchange when they differ from the end-of-step ones (secant
        #: schemes): the samples' omega_inner/omega_outer columns record these, the component's inputs
        self.sent_ring_speeds = None
        n, scheme, applied = self.n, self.scheme, system.applied_forces

        def rhs(tau, y):
            q, qd = y[:n], y[n:]
            Q = applied(q, qd, tau)
            if link is not None:
                ex, ey, vx, vy, _, _ = link.inputs(q, qd)
                Fx, Fy = scheme.force(tau, ex, ey, vx, vy)
                link.generalized_force(q, ex, ey, Fx, Fy, Q)
            qdd = system.accelerations(q, qd, tau, Q)[0]
            return np.concatenate((qd, qdd))
        self.rhs = rhs
        self.kernels = settings.kernels
        if self.kernels:
            self._setup_kernels(observe)

    # ------------------------------------------------------------------ compiled path
    def _setup_kernels(self, observe: Observer) -> None:
        """Pack the model for the kernels; preallocate the end-of-step evaluation and the row probes."""
        from mechanism.multibody import kernels as kn
        self._kn = kn
        system, link = self.system, self.link
        self._I, self._R = kn.pack(system)
        self._L, self._LR = kn.pack_link(system, link.joint if link is not None else None,
                                         link.contact_points if link is not None else "centres")
        self._W = np.zeros(kn.workspace_size(self._I))
        self._u = np.zeros(6)
        self._zero_fm = np.zeros(len(FORCE_MODEL_FIELDS))
        self._dy = np.zeros(2 * self.n)       # dy/dt at the end state (the sample, the next step's first stage)
        self._lam = np.zeros(system.m)
        self._end = (None, None)              # (y, t) that _dy, _lam and W's kinematics belong to
        self._cv = 0.0
        index = {c: i for i, c in enumerate(self.columns)}
        probes = [("time", 6, 0, 1.0), ("constraint_violation", 7, 0, 1.0), ("kinetic_energy", 8, 0, 1.0)]
        if self.link is not None:
            probes += [(c, 4, i, 1.0) for i, c in enumerate(("e_x", "e_y", "v_x", "v_y", "omega_inner",
                                                               "omega_outer"))]
        else:
            probes += [(c, 6, 0, 0.0) for c in ("e_x", "e_y", "v_x", "v_y")]
        probes += [("F_x", 5, 0, 1.0), ("F_y", 5, 1, 1.0)]
        source = {"q": 0, "qd": 1, "qdd": 2, "lam": 3}
        self._observe_in_kernel = hasattr(observe, "probes")
        if self._observe_in_kernel:
            probes += [(c, source[src], i, k) for c, src, i, k in observe.probes]
        self._probes = np.array([(index[p[0]], p[1], p[2]) for p in probes], np.int64).reshape(-1, 3)
        self._probe_scale = np.array([p[3] for p in probes], np.float64)
        self._sample_cols = np.array([index[c] for c in self.sample_names], np.int64)
        if len(self._sample_cols) and np.array_equal(np.diff(self._sample_cols), np.ones(len(self._sample_cols) - 1)):
            self._sample_cols = slice(int(self._sample_cols[0]), int(self._sample_cols[-1]) + 1)   # a faster write
        self._no_row = np.zeros(0)
        # an endpoint that copies its samples into the row (FmuEndpoint) when they are contiguous columns
        into = getattr(self.endpoint, "sample_into", None)
        self._sample_into = into if isinstance(self._sample_cols, slice) else None
        probe = getattr(self.reaction_force, "probe", None)   # (joint rows start, stop, x column, y column)
        self._react = np.array(probe if probe is not None and self.link is None else (), np.int64)

    def _finish_state(self, y: np.ndarray, t: float, rec: Recorder | None = None) -> None:
        """dy/dt and lambda at the end state y (its kinematics in W) with the exchanged force; with
        ``rec`` also the sample (one evaluation for both; see ``record``)."""
        if self.link is not None:
            fx, fy = self.force
            ex, ey = self.inputs[0], self.inputs[1]
        else:
            fx = fy = ex = ey = 0.0
        row = self._no_row if rec is None else rec.next_row()
        self._kn.finish(y, ex, ey, fx, fy, self._I, self._R, self._L, self._LR, self._W, self._u, self._dy,
                        self._lam, row, self._probes, self._probe_scale, t, self._cv, self._react, self._p1)
        self._end = (y, t)
        if rec is None:
            return
        n = self.n
        if self.link is None:
            if not len(self._react):
                row[rec.index["F_x"]], row[rec.index["F_y"]] = self.reaction_force(y[:n], self._lam)
        elif self._sample_into is not None:
            self._sample_into(row[self._sample_cols])
        elif self.sample_names:
            row[self._sample_cols] = self.endpoint.sample()
        if not self._observe_in_kernel:
            for name, value in self.observe(y[:n], y[n:], self._dy[n:], self._lam, t).items():
                row[rec.index[name]] = value
        if self.energy is not None and self.link is not None:
            for name, value in self.energy.update(t, y[:n], y[n:], self._lam, self._u.tolist(),
                                                  row[rec.index["kinetic_energy"]], self.integrals).items():
                row[rec.index[name]] = value
        if self.sent_ring_speeds is not None:     # the ring speeds the component was given (secant schemes)
            row[rec.index["omega_inner"]], row[rec.index["omega_outer"]] = self.sent_ring_speeds

    def _k1_valid(self, y: np.ndarray, t0: float, fm: np.ndarray) -> bool:
        """True if the stored end-of-step evaluation is this step's first RK4 stage (same state, time
        and force: F(t_ref = t0, e0, v0) of the force model is the exchanged force at the inputs)."""
        end_y, end_t = self._end
        if end_y is not y or end_t != t0:
            return False
        if self.link is None:
            return True
        u, f = self.inputs, self.force
        if fm[0] != t0 or fm[1] != f[0] or fm[2] != f[1]:
            return False
        if fm[7] == u[0] and fm[8] == u[1] and fm[9] == u[2] and fm[10] == u[3]:
            return True
        return not fm[11:].any()

    def start(self, y: np.ndarray) -> None:
        """Initialise the component with the inputs of state y at t = 0 (no-op without a component)."""
        if self.kernels:
            self._kn.prepare(y, 0.0, self._I, self._R, self._L, self._LR, self._W, self._u)
            self._cv = self._kn.max_violation(self._I, self._W) if self.system.m else 0.0
            self._end = (None, None)
        if self.endpoint is None:
            return
        n, link = self.n, self.link
        if self.contact_law is not None:
            self._angles0 = link.ring_angles(y[:n])
        u = tuple(self._u.tolist()) if self.kernels else link.inputs(y[:n], y[n:])
        out = self.endpoint.initialize(u)
        self.inputs, self.force = u, out[:2]
        self.scheme.push(Exchanged(0.0, *u[:4], *out))
        if self.scheme.uses_law:             # a model-based scheme: the law it integrates the step with
            self.scheme.bind_law(self.contact_law)
        if self.scheme.uses_tangent:
            self.mobility = link.mobility(y[:n], 0.0)

    def advance(self, y: np.ndarray, t0: float, h: float, step: int, t: float | None = None,
                rec: Recorder | None = None, finish: bool = True) -> np.ndarray:
        """One communication step [t0, t0 + h] from state y; returns the state at its end.

        ``t`` is the end time (default t0 + h; the fixed-step loop passes step * h). With ``rec`` the
        sample at the end of the step is appended to it (as ``record`` would, sharing its evaluation).
        ``finish=False`` (a pass of an iterated step, compiled path): the end-state evaluation is left to the
        caller (``communicate`` does it once, for the accepted pass).
        Raises ``RunFailure`` (``step`` names it) or the component's error.
        """
        if t is None:
            t = t0 + h
        y_start = y
        settings, scheme, endpoint, system = self.settings, self.scheme, self.endpoint, self.system
        fm = None
        if endpoint is not None:
            exchange = endpoint.exchange if rec is None or self._exchange_sampled is None else self._exchange_sampled
            pending = exchange(t0, h, self.inputs) if scheme.ordering == "jacobi" else None
            if scheme.uses_law and self.contact_law is not None:
                scheme.set_cage(self.cage_angle(y[:self.n]), self.inputs[4], self.inputs[5])
            scheme.begin_step(t0, h)
            m = substeps(h, scheme.substep_tangent(), self.mobility, settings.substep_limit,
                         settings.max_substeps) if scheme.uses_tangent else 1
            if scheme.uses_law:
                m = scheme.set_substeps(m, settings.max_substeps)
            if self.kernels:
                model = scheme.force_model(t0, h)
                fm = model.coefficients if model is not None else None
        else:
            m = 1
            fm = self._zero_fm if self.kernels else None
        if m > self.substeps_max:
            self.substeps_max = m
        self.substeps_total += m
        hs = h / m
        if fm is not None:     # the compiled step (kinematics of the end state included)
            if self._end[0] is not y:
                self._end = (None, None)
            if self.integrals is not None:   # (the account's arrays are passed also without one: see __init__)
                self._acc[:] = 0.0
            k1_valid = self._k1_valid(y, t0, fm)
            y = y.copy()     # advanced in place
            drift, finite = self._kn.advance(y, t0, hs, m, t, fm, self._dy, k1_valid, self._I, self._R, self._L,
                                             self._LR, self._W, self._u, self._acc, self._p1, self._stages)
            if finite and self.integrals is not None:
                self._energy_step(m, hs, finish)
        elif self.integrals is not None and endpoint is not None:   # the NumPy reference with the account
            y = self._advance_with_energy(y, t0, hs, m, finish)
            finite = bool(np.all(np.isfinite(y)))
            drift = None
            if self.kernels:
                self._kn.prepare(y, t, self._I, self._R, self._L, self._LR, self._W, self._u)
                drift = self._kn.max_violation(self._I, self._W)
        else:                  # the NumPy reference (or a scheme without a force model)
            rhs = self.rhs
            for k in range(m):
                y = rk4_step(rhs, t0 + k * hs, y, hs)
            finite = bool(np.all(np.isfinite(y)))
            drift = None
            if self.kernels:   # the compiled end-of-step evaluation follows
                self._kn.prepare(y, t, self._I, self._R, self._L, self._LR, self._W, self._u)
                drift = self._kn.max_violation(self._I, self._W)
        if not finite:
            raise RunFailure(step, t, "the mechanism state is not finite (the integration diverged)")
        n = self.n
        if system.m:
            if drift is None:
                drift = float(np.max(np.abs(system.phi(y[:n], t))))
            self._cv = drift
            if drift > settings.max_constraint_violation:
                raise RunFailure(step, t, f"constraint violation {drift:.3g} exceeds "
                                          f"{settings.max_constraint_violation:g} (the integration diverged)")
        if endpoint is not None:
            u = tuple(self._u.tolist()) if self.kernels else self.link.inputs(y[:n], y[n:])
            if scheme.ordering == "jacobi":
                out, used = pending, self.inputs
            else:
                sent = u if scheme.ring_speeds == "end" else self.link.secant_ring_speeds(u, y_start[:n], y[:n], h)
                self.sent_ring_speeds = sent[4:] if sent is not u else None
                out, used = exchange(t0, h, sent), u
            if not math.isfinite(sum(out)):
                raise RunFailure(step, t, f"the bearing returned a non-finite force {out[:2]}")
            scheme.push(Exchanged(t, *used[:4], *out))
            self.inputs, self.force = u, out[:2]
        if self.kernels:
            if finish:
                self._finish_state(y, t, rec)
        elif rec is not None:
            rec.add(self.row(t, y))
        return y

    def _integrate_energy(self, m: int, hs: float) -> None:
        """Add one step's integrals to ``integrals``: the mechanism's powers integrated by the RK4 stages (``_acc``)
        and the bearing side from the stage states (``EnergyAccount.stage_integrals``)."""
        dissipated, cage_work = self.energy.stage_integrals(self._stages, m, hs)
        acc = self._acc
        self.integrals += (dissipated, acc[0], cage_work, acc[1], acc[2])

    def _energy_step(self, m: int, hs: float, finish: bool) -> None:
        """After a step's integration: add its integrals now, or for a pass of an iterated step (``finish=False``)
        when ``communicate`` has accepted it (the last pass's stages stay in ``_stages``; the others are dropped)."""
        if finish:
            self._integrate_energy(m, hs)
        else:
            self._pending_energy = (m, hs)

    def _advance_with_energy(self, y: np.ndarray, t0: float, hs: float, m: int, finish: bool = True) -> np.ndarray:
        """``m`` RK4 substeps of the NumPy reference with the energy account: the mechanism's powers (drivers
        lambda . Phi_t, applied Q^A . q', the bearing force Q_link . q') as three more states of the same RK4
        step, and the stage states recorded for the bearing side, as ``kernels.advance`` does."""
        system, link, scheme, n = self.system, self.link, self.scheme, self.n
        stages = []

        def rhs(tau, ya):
            q, qd = ya[:n], ya[n:2 * n]
            Q = system.applied_forces(q, qd, tau)
            applied = float(np.dot(Q, qd))
            ex, ey, vx, vy, wi, wo = link.inputs(q, qd)
            Fx, Fy = scheme.force(tau, ex, ey, vx, vy)
            link.generalized_force(q, ex, ey, Fx, Fy, Q)
            qdd, lam = system.accelerations(q, qd, tau, Q)
            drive = float(np.dot(lam, system.phi_t(tau))) if system.m else 0.0
            stages.append((ex, ey, vx, vy, wi, wo, *link.ring_angles(q)))
            return np.concatenate((qd, qdd, (drive, applied, float(np.dot(Q, qd)) - applied)))

        ya = np.concatenate((y, np.zeros(3)))
        for k in range(m):
            ya = rk4_step(rhs, t0 + k * hs, ya, hs)
            q, qd = ya[:n], ya[n:2 * n]
            stages.append((*link.inputs(q, qd), *link.ring_angles(q)))
        self._stages[:5 * m] = stages
        self._acc[:] = ya[2 * n:]
        if np.all(np.isfinite(ya)):
            self._energy_step(m, hs, finish)
        return ya[:2 * n]

    def communicate(self, y: np.ndarray, t0: float, h: float, step: int, t: float | None = None,
                    rec: Recorder | None = None) -> np.ndarray:
        """One communication step: ``advance``, or for an iterative scheme (strong coupling) ``advance``
        repeated with rollback (FMU get/set state) until two passes' end-of-step force and eccentricity
        agree to ``settings.iteration_tol`` or ``settings.max_iterations`` passes were made. With ``rec`` the
        sample at the end of the step is appended (as ``advance`` does)."""
        scheme = self.scheme
        if scheme is None or not scheme.iterative:
            return self.advance(y, t0, h, step, t, rec)
        stats, limit = self.iterations, max(2, self.settings.max_iterations)
        law, n = self.contact_law, self.n
        start = scheme.past[-1]
        cage_start = self.cage_angle(y[:n]) if law is not None else 0.0
        snap = self.snapshot()
        previous = None
        predict = self.settings.iterate_where_needed
        # the passes do not evaluate their end state (finish=False): _dy, _lam stay the start state's, every
        # pass's first RK4 stage (the end of the accepted pass is evaluated once, below)
        start_end = self._end if self.kernels else None
        try:
            for passes in range(1, limit + 1):
                y_end = self.advance(y, t0, h, step, t, finish=False)
                end = scheme.past[-1]
                if previous is not None and scheme.converged(
                        previous, end, self.settings.iteration_tol, max(1e-6, math.hypot(end.e_x, end.e_y))):
                    break
                if passes == limit:
                    stats["not_converged"] += 1
                    break
                jumps = () if law is None else onset_jumps(law, start, cage_start, end, self.cage_angle(y_end[:n]))
                if predict and (not jumps if passes == 1 else _same_jumps(jumps, scheme.jumps)) \
                        and self._next_pass_negligible(scheme, end, t0, h):
                    stats["predicted"] += 1          # accepted without a further pass (and rollback)
                    break
                previous = end
                self.restore(snap)
                if self.kernels:
                    self._end = start_end
                scheme.set_trial(end, jumps)
        finally:
            scheme.set_trial(None)
            self.release(snap)
        if self.integrals is not None:                # the accepted pass's energy integrals
            self._integrate_energy(*self._pending_energy)
        stats["steps"] += 1
        stats["passes"] += passes
        stats["max_passes"] = max(stats["max_passes"], passes)
        t_end = t if t is not None else t0 + h
        if self.kernels:      # W and u hold the accepted pass's end kinematics: one evaluation, sample and next k1
            self._finish_state(y_end, t_end, rec)
        elif rec is not None:                        # the sample of the accepted (last) pass
            self.record(rec, t_end, y_end)
        return y_end

    def _next_pass_negligible(self, scheme, b: Exchanged, t0: float, h: float) -> bool:
        """The predictor-corrector test of ``iterate_where_needed``: would a further pass move the end of the step
        by less than ``iteration_tol`` (the scales of ``scheme.converged``)?

        The next pass's force model differs from this pass's by D(s) with D(0) = 0 (both give F_n at the start
        state) and, along this pass, D(h) = F* - F_k(t_n + h, e*, v*): the component's end force against this
        pass's model there; about linear in s in between. Acting on the rings' relative mobility g
        (``mobility``), it moves the end state by de = g |D(h)| h^2 / 6, dv = g |D(h)| h / 2 and the end force
        by k de + c dv (k, c: largest eigenvalues of the end tangent matrices). Then the pass is accepted: its
        distance to the fixed point is about that change (the pass-to-pass map contracts by g (k h^2/6 + c h/2),
        about 0.01 at 1200 rpm and h = 1e-5 s)."""
        model = scheme.force_model(t0, h)
        if self.mobility <= 0.0:
            return False
        if model is not None:
            fx, fy = model(b.t, b.e_x, b.e_y, b.v_x, b.v_y)
            dx, dy = b.F_x - fx, b.F_y - fy
        else:         # a model-based scheme (law-model): its own end mismatch, on its first pass only
            mismatch = scheme.end_mismatch(b) if hasattr(scheme, "end_mismatch") else None
            if mismatch is None:
                return False
            dx, dy = mismatch
        d = math.hypot(dx, dy) * self.mobility
        de, dv = d * h * h / 6.0, d * h / 2.0
        k = max(sym_eig_max(b.k_xx, b.k_xy, b.k_yy), 0.0)
        c = max(sym_eig_max(b.c_xx, b.c_xy, b.c_yy), 0.0)
        tol = self.settings.iteration_tol
        return (k * de + c * dv <= tol * max(1.0, abs(b.F_x), abs(b.F_y))
                and de <= tol * max(1e-6, math.hypot(b.e_x, b.e_y)))

    def cage_angle(self, q: np.ndarray) -> float:
        """The kinematic cage angle [rad] at q (``energy.kinematic_cage_angle``; needs ``contact_law``)."""
        return kinematic_cage_angle(self.contact_law, self.link, self._angles0, q)

    def record(self, rec: Recorder, t: float, y: np.ndarray) -> None:
        """Append the sample at time t of the state y (the last one ``start``/``advance`` reached) to ``rec``."""
        if not self.kernels:
            rec.add(self.row(t, y))
            return
        if self._end[0] is not y or self._end[1] != t:
            self._kn.prepare(y, t, self._I, self._R, self._L, self._LR, self._W, self._u)
        self._finish_state(y, t, rec)

    def row(self, t: float, y: np.ndarray) -> dict:
        """The sample at time t for the end-of-step state y: observables, inputs, force, component samples
        (the NumPy reference of ``record``)."""
        system, link, n = self.system, self.link, self.n
        q, qd = y[:n], y[n:]
        force = self.force
        Q = system.applied_forces(q, qd, t)
        if link is not None:
            link.generalized_force(q, self.inputs[0], self.inputs[1], *force, Q)
        qdd, lam = system.accelerations(q, qd, t, Q)
        row = self.observe(q, qd, qdd, lam, t)
        if link is not None:
            ex, ey, vx, vy, wi, wo = self.inputs
            row.update(e_x=ex, e_y=ey, v_x=vx, v_y=vy, omega_inner=wi, omega_outer=wo,
                       F_x=force[0], F_y=force[1])
            row.update(zip(self.sample_names, self.endpoint.sample()))
        else:
            row.update(e_x=0.0, e_y=0.0, v_x=0.0, v_y=0.0)
            row["F_x"], row["F_y"] = self.reaction_force(q, lam)
        row["time"] = t
        row["constraint_violation"] = float(np.max(np.abs(system.phi(q, t)))) if system.m else 0.0
        row["kinetic_energy"] = system.kinetic_energy(qd)
        if self.energy is not None:
            row.update(self.energy.update(t, q, qd, lam, self.inputs, row["kinetic_energy"], self.integrals))
        if self.sent_ring_speeds is not None:     # the ring speeds the component was given (secant schemes)
            row["omega_inner"], row["omega_outer"] = self.sent_ring_speeds
        return row

    def snapshot(self):
        """Everything ``advance`` changes besides y, to roll back to (free it with ``release``)."""
        endpoint = self.endpoint
        fmu_state = endpoint.get_state() if endpoint is not None else None
        past = tuple(self.scheme.past) if self.scheme is not None else ()
        integrals = self.integrals.copy() if self.integrals is not None else None
        return past, self.inputs, self.force, fmu_state, integrals

    def restore(self, snap) -> None:
        """Roll back to ``snap`` (which stays valid for another restore)."""
        past, self.inputs, self.force, fmu_state, integrals = snap
        if integrals is not None:
            self.integrals[:] = integrals
        if self.scheme is not None:
            self.scheme.past.clear()
            self.scheme.past.extend(past)
        if self.endpoint is not None:
            self.endpoint.set_state(fmu_state)
        if self.kernels:
            self._end = (None, None)

    def release(self, snap) -> None:
        if self.endpoint is not None and snap[3] is not None:
            self.endpoint.free_state(snap[3])


def _same_jumps(a, b, tol: float = 1e-3) -> bool:
    """Two passes located the same contact onsets in the step (``onset_jumps``): same count, positions within
    ``tol`` of the step, jumps within ``tol`` relative."""
    return len(a) == len(b) and all(abs(x[0] - y[0]) <= tol and math.hypot(x[1] - y[1], x[2] - y[2])
                                    <= tol * math.hypot(y[1], y[2]) for x, y in zip(a, b))


def run_master(system: System, q0: np.ndarray, qd0: np.ndarray, settings: MasterSettings,
               observe: Observer, link: BearingLink | None = None, endpoint: Endpoint | None = None,
               reaction_force: Callable[[np.ndarray, np.ndarray], tuple[float, float]] | None = None,
               meta: dict | None = None, energy: EnergyAccount | None = None, contact_law=None,
               sink=None) -> RunResult:
    """Integrate the mechanism from (q0, qd0) to ``settings.t_end``, co-simulated with ``endpoint`` if given.

    ``energy``: an energy account (``mechanism.cosim.energy``) updated at every sample, adding its columns.
    ``contact_law``: the bearing's ``BallBearing`` for the iterated scheme's contact-onset correction (default:
    the energy account's or the in-process endpoint's; a run through an FMU without either gets none).

    For the ideal joint pass ``link=endpoint=None`` and ``reaction_force(q, lam)`` giving the
    joint's force on the housing body, recorded as F_x, F_y.

    ``sink``: the samples are handed to it as they are recorded (``record.Recorder``; e.g.
    ``mechanism.output.stream.TableStream``, which writes timeseries.csv during the run) and the result is its.
    """
    h = settings.step
    n_steps = int(round(settings.t_end / h))
    every = max(1, int(round(settings.output_interval / h)))
    loop = CouplingLoop(system, settings, observe, link, endpoint, reaction_force, energy, contact_law)
    rec = Recorder(loop.columns, n_steps // every + 2, sink)
    info = dict(meta or {})
    info.update(step_s=h, output_interval_s=every * h, t_end_s=n_steps * h,
                scheme=loop.scheme.name if loop.scheme else "none", endpoint=getattr(endpoint, "kind", "none"))
    y = np.concatenate((q0, qd0)).astype(float)
    step, t = 0, 0.0
    from tqdm import tqdm  # here, not at the top: SliderCrank.fmu packs this module and needs no tqdm at runtime
    bar = tqdm(total=n_steps, desc=settings.description, unit="step", disable=not settings.progress,
               mininterval=0.5, leave=False)
    poll = getattr(observe, "poll", None) if loop.kernels and loop._observe_in_kernel else None
    warmup = None
    completed = False
    if settings.compiled_loop and getattr(endpoint, "kind", None) in ("in-process", "fmu"):
        from mechanism.cosim import compiled_driver
        if loop.kernels:   # a first run: the loop's own functions compile in a second process (None if cached)
            law_model = bool(getattr(loop.scheme, "uses_law", False) and loop.contact_law is not None)
            warmup = compiled_driver.start_warmup((endpoint.kind == "fmu", law_model))
    try:
        await_warmup(loop, None if poll is None else lambda: poll(0.0))
        if warmup is not None:
            bar.set_postfix_str("compiling kernels (first run)")
        loop.start(y)
        loop.record(rec, 0.0, y)
        compiled = None
        if (settings.compiled_loop and getattr(endpoint, "kind", None) in ("in-process", "fmu")
                and compiled_driver.eligible(loop)):
            compiled = compiled_driver.CompiledLoop(loop, rec, y, every, n_steps)
        compiling = compiled is not None and not compiled_driver.cached()
        if compiling:     # the first chunk compiles the step (tens of seconds): say so, not an ETA from it
            bar.set_postfix_str("compiling kernels (first run)")
            # its functions in the cache: the first chunk loads them (a noted signal still stops the run)
            compiled_driver.finish_warmup(warmup, poll=None if poll is None else lambda: poll(0.0))
        while compiled is not None and step < n_steps:     # chunks of 500 steps: the bar and the poll between
            last = min(n_steps, (step // 500 + 1) * 500)
            y = compiled.run(step + 1, last, y)
            if compiled.failure is not None:
                raise RunFailure(*compiled.failure)
            step, t = last, last * h
            if compiling:   # the rate and ETA from here on, without the compile
                compiling = False
                bar.set_postfix_str("", refresh=False)
                bar.reset()
            if step % 500 == 0:
                bar.update(500)
                if poll is not None:
                    poll(t)
        for step in range(1, n_steps + 1) if compiled is None else ():
            t0 = (step - 1) * h
            t = step * h
            # a sample every `every` steps, and the run's end also when it is off that stride
            y = loop.communicate(y, t0, h, step, t, rec if step % every == 0 or step == n_steps else None)
            if step % 500 == 0:
                bar.update(500)
                if poll is not None:   # e.g. a signal noted by the driver (mechanism.run), when observe is compiled
                    poll(t)
        completed = True
    except RunFailure as err:
        info["failure"] = {"step": err.step, "time_s": err.time, "cause": err.cause}
        return finish(rec, info, "failed", str(err), endpoint, bar, loop)
    except Exception as err:  # an error status from the component, a singular matrix, ...
        cause = f"{type(err).__name__}: {err}"
        info["failure"] = {"step": step, "time_s": t, "cause": cause}
        return finish(rec, info, "failed", f"stopped at step {step} (t = {t:.9g} s): {cause}",
                      endpoint, bar, loop)
    finally:
        if warmup is not None and completed:   # not waited for (the Python loop ran): end it; kept: left to the
            compiled_driver.finish_warmup(warmup, 0)    # ideal counterpart's run (compiled_driver.await_later)
        elif warmup is not None:   # failed or interrupted: no run follows that would wait for it
            compiled_driver.drop_warmup(warmup)
    return finish(rec, info, "completed", "", endpoint, bar, loop)


def await_warmup(loop: CouplingLoop, poll: Callable[[], None] | None = None) -> None:
    """Before a run whose Python code calls the kernels: wait for a first run's warm-up process that is still
    compiling one of them (``compiled_driver.await_later``: a law-model run's ideal counterpart's
    ``kernels.advance``), calling ``poll`` as it waits; nothing if there is none (only ``compiled_driver`` starts
    one, so without it imported there is none)."""
    driver = sys.modules.get("mechanism.cosim.compiled_driver")
    if loop.kernels and driver is not None:
        driver.await_later(poll=poll)


def finish(rec: Recorder, info: dict, status: str, message: str, endpoint, bar, loop: CouplingLoop) -> RunResult:
    """Close the progress bar and wrap the samples and counters into a RunResult."""
    bar.close()
    info["substeps_max"] = loop.substeps_max
    info["substeps_total"] = loop.substeps_total
    if loop.integrals is not None and status == "completed" and rec.count > 1:
        # the energy residual's two parts [J]: the mechanism's (T - T_0 - W_drive - W_applied - W_link, the RK4
        # integration's error) and the interface's (W_link + V - V_0 + D - W_cage: the work of the bearing
        # force the mechanism felt against what the law stores and dissipates along the trajectory, i.e. the
        # energy the coupling created)
        first, last = rec.first_row, rec.last_row
        kinetic = rec.index["kinetic_energy"]
        drive, applied, link_work = loop.integrals[1], loop.integrals[3], loop.integrals[4]
        mechanism = float(last[kinetic] - first[kinetic] - drive - applied - link_work)
        info["energy_interface_work_J"] = float(link_work)
        info["energy_residual_mechanism_J"] = mechanism
        info["energy_residual_coupling_J"] = float(last[rec.index["energy_residual"]]) - mechanism
    it = loop.iterations
    if it["steps"]:
        info.update(iteration_passes_mean=it["passes"] / it["steps"], iteration_passes_max=it["max_passes"],
                    iteration_not_converged=it["not_converged"], iteration_predicted=it["predicted"])
    if endpoint is not None:
        info["component_calls"] = endpoint.calls
        if hasattr(endpoint, "life_outputs"):  # bearing rating life at the end (docs/bearing-life.md)
            info["life_outputs"] = endpoint.life_outputs()
    return rec.result(info, status, message)
