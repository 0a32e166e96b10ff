"""The monolithic reference: mechanism and bearing force law in one ODE, solved by scipy's stiff integrators.

State y = [q, q', cage_angle]: eq. (9) with Baumgarte for q'', eq. (16) for the cage angle,
the bearing force (eq. 18-19) evaluated in-process by the same ``fmu_bearing`` module the
FMU wraps, at every right-hand-side call. Error control (tight tolerances, adaptive
steps) makes this the reference that co-simulation error is measured against.

The integrator is stepped by hand (``OdeSolver.step``) and sampled through its dense output
at the output grid, so a failure keeps what was computed up to it.

Cost (issue 11): the right-hand side is compiled by default (``monolithic_kernel``: the multibody kernels, the
compiled law, the cage speed and the account's powers; ~10 us a call against ~280 us for the NumPy one, which
``compiled=False`` keeps as the reference the tests hold the kernel against). LSODA at rtol 1e-11 runs mostly
in its non-stiff (Adams) mode, ~3 calls per step, so finite-difference Jacobians are not where the time goes;
what is left is roughly scipy's per-step overhead (~40 %), the samples (~25 %) and the calls (~20 %).

Energy account (issue 12): the account's integrals (damping dissipation D, work of the drivers, of the cage
and of the applied forces; ``mechanism.cosim.energy``) are four more states of the ODE, y = [q, q', cage, D,
W_drive, W_cage, W_applied], whose derivatives are the powers ``energy.account_powers`` at the same state
(no feedback into the motion). The integrator's error control covers them, and with the contact onsets
located as events no step straddles the jump of the damping power C v_r^2 at an onset: the account's
residual R = T + V + D - W_drive - W_applied - W_cage - T_0 - V_0 is then the integrator's error, not a
quadrature floor of the samples (``energy_states=False``: the sampled account of ``EnergyAccount``).
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.integrate import BDF, LSODA, Radau
from scipy.optimize import brentq
from tqdm import tqdm

from fmu_bearing.ball_bearing import BallBearing, BearingInputError
from mechanism.cosim.coupling.implicit import ball_deflections
from mechanism.cosim.energy import ENERGY_COLUMNS, EnergyAccount, account_powers
from mechanism.cosim.joint import BearingLink
from mechanism.cosim.master import Observer
from mechanism.cosim.record import BASE_COLUMNS, Recorder, RunResult
from mechanism.multibody.solver import System

METHODS = {"Radau": Radau, "BDF": BDF, "LSODA": LSODA}


def tolerances(system: System, rtol: float) -> np.ndarray:
    """Absolute tolerances per state: 1e-12 m / rad on positions, 1e-9 on velocities, 1e-10 rad on the cage.

    The eccentricity is ~1e-5 m, so positions need an absolute tolerance far below 1e-7 m
    (1 % of it); rtol alone would let the 0.1 m body positions swamp it.
    """
    n = system.n
    return np.concatenate((np.full(n, 1e-12), np.full(n, 1e-9), [1e-10])) * max(rtol / 1e-9, 1e-3)


#: absolute tolerance [J] at rtol 1e-9 of the energy account's quadrature states (scaled with rtol as the
#: others): the dissipation over a run is ~1e-4 ... 1e-2 J, the drive work ~0.1 J
ENERGY_ATOL = 1e-10


def run_monolithic(system: System, link: BearingLink, bearing: BallBearing, q0: np.ndarray, qd0: np.ndarray,
                   t_end: float, output_interval: float, observe: Observer, method: str = "LSODA",
                   rtol: float = 1e-9, progress: bool = True, meta: dict | None = None,
                   events: bool = True, energy_states: bool = True, compiled: bool = True) -> RunResult:
    """Integrate the coupled ODE to ``t_end`` and sample it every ``output_interval`` (SI).

    ``events``: locate every ball's entry into and exit from the load zone (delta_r = 0, eq. 18) on the
    dense output (Brent's method to 1e-14 s) and restart the integrator there, so that no step straddles
    the jump of the damping force C v_r at a contact onset (meta ``contact_events``).
    ``energy_states``: integrate the energy account's integrals as ODE states (module docstring); False: the
    sampled account (quadrature of the samples, ``EnergyAccount``).
    ``compiled``: the right-hand side, the samples' forces and the event function through the numba kernels
    (``monolithic_kernel``, held against the NumPy right-hand side by tests); False: the NumPy reference
    (``System`` + ``BallBearing`` + ``energy.account_powers``), the same ODE.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    n = system.n
    nb = bearing.n_balls
    sample_names = ["cage_angle", "loaded_balls", "max_ball_load"] + [f"ball_load_{r + 1}" for r in range(nb)]
    columns = list(BASE_COLUMNS) + sample_names + list(ENERGY_COLUMNS)
    energy = EnergyAccount(system, link, bearing)
    n_out = int(round(t_end / output_interval))
    times = np.arange(n_out + 1) * output_interval
    rec = Recorder(columns, n_out + 1)
    counter = {"rhs": 0, "events": 0}

    if compiled:
        rhs_of_state, sample, zone, ball_loads = _compiled_pieces(system, link, bearing, energy_states)
    else:
        rhs_of_state = numpy_rhs(system, link, bearing, energy_states)
        sample, zone, ball_loads = _numpy_pieces(system, link, bearing)

    def rhs(t, y):
        counter["rhs"] += 1
        return rhs_of_state(t, y)

    def record(t, y):
        y = np.ascontiguousarray(y, dtype=float)
        q, qd, cage = y[:n], y[n:2 * n], float(y[2 * n])
        qdd, lam, (ex, ey, vx, vy, wi, wo), (fx, fy, n_loaded, f_max), violation = sample(t, y)
        row = observe(q, qd, qdd, lam, t)
        row.update(time=t, e_x=ex, e_y=ey, v_x=vx, v_y=vy, omega_inner=wi, omega_outer=wo, F_x=fx, F_y=fy,
                   cage_angle=cage, loaded_balls=n_loaded, max_ball_load=f_max,
                   constraint_violation=violation, kinetic_energy=system.kinetic_energy(qd))
        row.update({f"ball_load_{r + 1}": float(ball_loads[r]) for r in range(nb)})
        if energy_states:
            dissipated, drive, cage_work, applied = (float(v) for v in y[2 * n + 1:2 * n + 5])
            potential = bearing.elastic_energy(ex, ey, cage)
            total = row["kinetic_energy"] + potential
            if not start_energy:
                start_energy.append(total)
            row.update(contact_energy=potential, damping_dissipation=dissipated, drive_work=drive,
                       cage_work=cage_work, applied_work=applied,
                       energy_residual=total + dissipated - drive - applied - cage_work - start_energy[0])
        else:
            row.update(energy.update(t, q, qd, lam, (ex, ey, vx, vy, wi, wo), row["kinetic_energy"]))
        rec.add(row)

    start_energy: list = []
    y0 = np.concatenate((q0, qd0, [bearing.params.cage_angle_start], [0.0] * (4 if energy_states else 0)))
    y0 = y0.astype(float)
    info = dict(meta or {})
    info.update(method=method, rtol=rtol, t_end_s=float(times[-1]), output_interval_s=output_interval,
                endpoint="monolithic", scheme="none",
                energy_account="ode-states" if energy_states else "sampled")
    bar = tqdm(total=100, desc=f"monolithic ({method})", unit="%", disable=not progress, leave=False,
               mininterval=0.5)
    k = 0
    try:
        def start(t0, y, first_step=None):
            atol = tolerances(system, rtol)
            if energy_states:
                atol = np.concatenate((atol, np.full(4, ENERGY_ATOL * max(rtol / 1e-9, 1e-3))))
            return METHODS[method](rhs, t0, y, float(times[-1]), rtol=rtol, atol=atol,
                                   max_step=output_interval * 10, first_step=first_step)

        solver = start(0.0, y0)
        record(0.0, y0)
        k = 1
        done = 0
        loaded = [d > 0.0 for d in zone(y0)]
        while solver.status == "running":
            msg = solver.step()
            if solver.status == "failed":
                raise RuntimeError(f"{method} failed: {msg}")
            t_stop, restart = solver.t, None
            dense = _Lazy(solver)
            now = [d > 0.0 for d in zone(solver.y)]
            if events and now != loaded:
                t_a = solver.t_old
                first = None
                for r in (r for r in range(nb) if now[r] != loaded[r]):
                    def delta(s, r=r, dense=dense):
                        return zone(dense(s))[r]
                    if (delta(t_a) > 0.0) != (delta(t_stop) > 0.0):
                        t_r = brentq(delta, t_a, t_stop, xtol=1e-14, rtol=4 * np.finfo(float).eps)
                        if first is None or t_r < first[0]:
                            first = (t_r, r)
                if first is not None and first[0] < t_stop:
                    t_stop, restart = first
            while k < len(times) and times[k] <= t_stop + 1e-15:
                record(float(times[k]), dense(times[k]))
                k += 1
            if restart is not None:
                y_ev = dense(t_stop)
                loaded[restart] = not loaded[restart]
                counter["events"] += 1
                # restart with the last step size (at most the remaining span): an automatic first step
                # can probe states far outside the clearance, which the force law refuses
                previous = max(solver.t - solver.t_old, 1e-12)
                solver = start(t_stop, y_ev, min(previous, float(times[-1]) - t_stop))
            else:
                loaded = now
            pct = int(100 * solver.t / times[-1])
            if pct > done:
                bar.update(pct - done)
                done = pct
        status, message = "completed", ""
    except Exception as err:
        t_fail = times[min(k, len(times) - 1)]
        status = "failed"
        message = f"stopped near sample {k} (t = {t_fail:.9g} s): {type(err).__name__}: {err}"
        info["failure"] = {"sample": k, "time_s": float(t_fail), "cause": str(err)}
    bar.close()
    info["rhs_calls"] = counter["rhs"]
    info["contact_events"] = counter["events"]
    return RunResult(rec.columns, rec.table().copy(), info, status, message)


def _forces(system: System, link: BearingLink, bearing: BallBearing, t: float, q: np.ndarray, qd: np.ndarray,
            cage: float, out_loads: list | None = None):
    """(Q, the law's output, the link's inputs) at a state (NumPy): eq. (10)-(12), (18)-(19), (20)-(23)."""
    ex, ey, vx, vy, wi, wo = link.inputs(q, qd)
    bearing.check_inputs(ex, ey, vx, vy, wi, wo)
    f = bearing.evaluate(ex, ey, vx, vy, cage, wi, wo, out_loads)
    Q = link.generalized_force(q, ex, ey, f.F_x, f.F_y, system.applied_forces(q, qd, t))
    return Q, f, (ex, ey, vx, vy, wi, wo)


def numpy_rhs(system: System, link: BearingLink, bearing: BallBearing,
              energy_states: bool = True) -> Callable[[float, np.ndarray], np.ndarray]:
    """The reference right-hand side f(t, y) of y = [q, q', cage, (D, W_drive, W_cage, W_applied)] in NumPy:
    eq. (9) with Baumgarte for q'', eq. (16) for the cage, ``energy.account_powers`` for the account's states."""
    n = system.n

    def rhs(t, y):
        q, qd, cage = y[:n], y[n:2 * n], y[2 * n]
        Q, f, u = _forces(system, link, bearing, t, q, qd, cage)
        qdd, lam = system.accelerations(q, qd, t, Q)
        head = (qd, qdd, [bearing.cage_velocity(u[4], u[5])])                              # eq. (9), (16)
        if not energy_states:
            return np.concatenate(head)
        el = bearing.evaluate(u[0], u[1], 0.0, 0.0, cage, u[4], u[5])
        return np.concatenate(head + (account_powers(system, bearing, t, q, qd, lam, u, (f.F_x, f.F_y),
                                                     (el.F_x, el.F_y)),))
    return rhs


def compiled_rhs(system: System, link: BearingLink, bearing: BallBearing,
                 energy_states: bool = True) -> Callable[[float, np.ndarray], np.ndarray]:
    """``numpy_rhs`` through the numba kernel (``monolithic_kernel.rhs``)."""
    return _compiled_pieces(system, link, bearing, energy_states)[0]


def _numpy_pieces(system: System, link: BearingLink, bearing: BallBearing):
    """(sample, zone, ball loads) of the NumPy path: the recorded quantities of a state and the balls'
    deflections (the event functions)."""
    n = system.n
    loads = [0.0] * bearing.n_balls

    def sample(t, y):
        q, qd, cage = y[:n], y[n:2 * n], float(y[2 * n])
        Q, f, u = _forces(system, link, bearing, t, q, qd, cage, loads)
        qdd, lam = system.accelerations(q, qd, t, Q)
        return (qdd, lam, u, (f.F_x, f.F_y, f.loaded_balls, f.max_ball_load),
                float(np.max(np.abs(system.phi(q, t)))))

    def zone(y):
        ex, ey = link.inputs(y[:n], y[n:2 * n])[:2]
        return ball_deflections(bearing, ex, ey, float(y[2 * n]))
    return sample, zone, loads


def _compiled_pieces(system: System, link: BearingLink, bearing: BallBearing, energy_states: bool):
    """(rhs, sample, zone, ball loads) through the numba kernels (``monolithic_kernel``)."""
    from mechanism.cosim import monolithic_kernel as mk
    from mechanism.multibody import kernels as kn
    n = system.n
    arr = mk.Arrays(system, link, bearing)
    size = 2 * n + 1 + (4 if energy_states else 0)
    args = (arr.I, arr.R, arr.L, arr.LR, arr.P, arr.W, arr.u, arr.out, arr.loads, arr.limit, energy_states)
    kernel = mk.rhs

    def refused():
        """The bearing's own error for the inputs the kernel refused (``BallBearing.check_inputs``)."""
        bearing.check_inputs(*(float(v) for v in arr.u))
        return BearingInputError(f"bearing inputs refused: {arr.u.tolist()}")

    def rhs(t, y):
        dy = np.empty(size)
        if kernel(t, y, *args, dy):
            raise refused()
        return dy

    def sample(t, y):
        dy = np.empty(size)
        if kernel(t, y, *args, dy):
            raise refused()
        lam = np.empty(system.m)
        kn.multipliers(arr.I, arr.W, lam)
        o = arr.out
        return (dy[n:2 * n], lam, tuple(float(v) for v in arr.u),
                (float(o[0]), float(o[1]), int(o[8]), float(o[9])), float(kn.max_violation(arr.I, arr.W)))

    deflection = np.empty(bearing.n_balls)

    def zone(y):
        mk.deflections(y, arr.I, arr.L, arr.LR, arr.W, arr.u, bearing.half_clearance, deflection)
        return deflection.tolist()
    return rhs, sample, zone, arr.loads


class _Lazy:
    """The solver's dense output over its last step, built on the first call (a step with no sample and no
    event does not need it)."""

    def __init__(self, solver):
        self._solver, self._dense = solver, None

    def __call__(self, t):
        if self._dense is None:
            self._dense = self._solver.dense_output()
        return self._dense(t)
