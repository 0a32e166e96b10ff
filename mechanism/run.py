"""The one driver: a run's configuration -> the system -> the master (or the monolithic reference) -> a RunResult.

``RunConfig`` is what the command line ``python -m mechanism run`` (and ``--ssp``, and every study)
fills in; ``run`` builds the paper's slider-crank (``mechanism.systems.slider_crank``) on the generic
multibody core (``mechanism.multibody``), the bearing link and component (``mechanism.cosim``), and
hands them to the fixed-step master, the adaptive master (``run_adaptive``) or the monolithic
reference. Writing files is ``mechanism.output``'s job.
"""
from __future__ import annotations

import argparse
import numbers
import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import from_values as bearing_parameters
from fmu_bearing.parameters import validate as validate_bearing
from mechanism.cosim.adaptive import AdaptiveSettings
from mechanism.cosim.adaptive import run_adaptive as run_adaptive_master
from mechanism.cosim.coupling import DEFAULT_SCHEME
from mechanism.cosim.energy import EnergyAccount
from mechanism.cosim.endpoints import InProcessEndpoint, fmu_endpoint
from mechanism.cosim.joint import BearingLink
from mechanism.cosim.master import MasterSettings, RunFailure, run_master
from mechanism.cosim.record import RunResult
from mechanism.multibody.solver import System
from mechanism.systems.slider_crank import (SliderCrankParameters, build, ideal_reaction, initial_state,
                                            slider_crank_observer)

JOINTS = ("bearing", "ideal", "clearance")
MODES = ("cosim", "inprocess", "monolithic")
FMU_NAMES = {"bearing": "BallBearing", "clearance": "JournalClearance"}
#: the default communication step [s]: the default scheme's (law-model's) full-run figures (start-up impacts
#: included) within 0.03 % of the monolithic reference at every paper operating point (docs/coupling.md,
#: "The default scheme and step")
DEFAULT_STEP = 1e-5


#: documented ranges of RunConfig's numbers (docs/robustness.md): name -> (min, max, unit).
#: Beyond them a run is meaningless (a step of 1e300 s) or numerically absurd, so they are errors.
RANGES = {
    "rpm": (1e-3, 1e5, "rpm"),
    "revs": (1e-4, 1e3, "revolutions"),
    "step": (1e-9, 1e-2, "s"),
    "output_interval": (1e-9, 1.0, "s"),
    "rtol": (1e-14, 1e-2, ""),
}


@dataclass
class RunConfig:
    """Everything that defines a run (SI, except rpm). ``settings`` are start values for the bearing component.

    Numbers outside ``RANGES``, and a step or output interval longer than the run, are ``ValueError``s
    naming the range (a run with no step would otherwise "complete" with one sample).
    """

    rpm: float = 1200.0
    revs: float = 2.0
    balls: int | None = None
    joint: str = "bearing"
    mode: str = "cosim"
    step: float = DEFAULT_STEP
    output_interval: float = 1e-5
    settings: dict = field(default_factory=dict)
    scheme: str = DEFAULT_SCHEME
    contact_points: str = "centres"
    gravity: bool = False
    fmu: str | None = None
    method: str = "LSODA"
    rtol: float = 1e-9
    progress: bool = True
    record_every: int | None = None      # record every N-th communication step (overrides output_interval)

    def __post_init__(self):
        if self.joint not in JOINTS:
            raise ValueError(f"joint must be one of {JOINTS}, not {self.joint!r}")
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, not {self.mode!r}")
        if self.record_every is not None:
            if isinstance(self.record_every, bool) or int(self.record_every) != self.record_every \
                    or self.record_every < 1:
                raise ValueError(f"record_every must be a positive integer, not {self.record_every!r}")
            self.output_interval = self.record_every * self.step
        for name, (lo, hi, unit) in RANGES.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not lo <= value <= hi:
                raise ValueError(f"{name} = {value!r} is outside its range [{lo:g}, {hi:g}] {unit}".rstrip())
        if self.balls is not None and (isinstance(self.balls, bool) or not isinstance(self.balls, numbers.Integral)):
            raise ValueError(f"balls = {self.balls!r} must be an integer")
        if self.joint == "bearing":   # the bearing's parameters before any run (BearingParameterError)
            validate_bearing(bearing_parameters(self.component_settings))
        t_end = self.revs * self.crank_period
        for name in ("step", "output_interval"):
            if getattr(self, name) > t_end:
                raise ValueError(f"{name} = {getattr(self, name)!r} s is longer than the run "
                                 f"({self.revs:g} revolutions at {self.rpm:g} rpm = {t_end:.6g} s)")

    @property
    def crank_period(self) -> float:
        """Duration of one crank revolution [s]."""
        return 60.0 / self.rpm

    @property
    def component_settings(self) -> dict:
        values = dict(self.settings)
        if self.balls is not None:
            values["n_balls"] = int(self.balls)
        return values


def parse_setting(text: str) -> tuple[str, object]:
    """NAME=VALUE -> (name, int | float | bool); the component converts to its variable's type."""
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"--set expects NAME=VALUE, got {text!r}")
    name, raw = (s.strip() for s in text.split("=", 1))
    low = raw.lower()
    if low in ("true", "false"):
        return name, low == "true"
    try:
        return name, int(raw)
    except ValueError:
        try:
            return name, float(raw)
        except ValueError:
            raise argparse.ArgumentTypeError(f"--set {name}: {raw!r} is not a number") from None


def fmu_path(config: RunConfig) -> Path:
    """The component FMU for the run: ``--fmu`` as given, else dist/<Name>.fmu, (re)built when it is
    missing or older than its sources (a stale FMU is never used silently)."""
    if config.fmu:
        return Path(config.fmu)
    import build_fmu
    name = FMU_NAMES[config.joint]
    path = Path("dist") / f"{name}.fmu"
    if not build_fmu.is_fresh(path, name):
        build_fmu.build(Path("dist"), names=[name])
    return path


def clearance_per_side(config: RunConfig) -> float:
    """Free play of the joint per side [m]: P_d/2 for the ball bearing, c for the journal-bushing joint."""
    if config.joint == "bearing":
        return 0.5 * bearing_parameters(config.component_settings).radial_clearance
    if config.joint == "clearance":
        from fmu_bearing.clearance_joint import ClearanceParameters
        value = config.settings.get("radial_clearance")
        return float(value) if value is not None else ClearanceParameters().radial_clearance
    return 0.0


def run_meta(config: RunConfig) -> dict:
    """What every run of ``config`` records in its meta before it starts: the configuration, the crank period [s]
    and the joint's free play per side [m] (the figures' titles and scales read them: ``output.figures.Plan``)."""
    return {"config": asdict(config), "crank_period_s": config.crank_period,
            "clearance_per_side_m": clearance_per_side(config)}


def contact_law(config: RunConfig) -> BallBearing | None:
    """The ball bearing's law for the iterated scheme's contact-onset correction (None for the journal-clearance
    joint): given to the master whether or not an energy account is recorded (the physics must not depend on it)."""
    return BallBearing(bearing_parameters(config.component_settings)) if config.joint == "bearing" else None


def energy_account(config: RunConfig, system: System, link: BearingLink) -> EnergyAccount | None:
    """The run's energy account (``mechanism.cosim.energy``): the ball bearing's law in-process; None for
    the journal-clearance joint (its account is not implemented)."""
    if config.joint != "bearing":
        return None
    return EnergyAccount(system, link, BallBearing(bearing_parameters(config.component_settings)))


class Interrupted(RunFailure):
    """Raised inside the master (at a sample) after SIGINT/SIGTERM: the run stops with the samples so far."""


class _Stop:
    """The signal received while ``stop_on_signals`` is active (None: none)."""

    signal: str | None = None


@contextmanager
def stop_on_signals():
    """While active (main thread only), SIGINT and SIGTERM only note the signal; the master stops at its next
    sample (``_interruptible``) and the run ends with status "interrupted" and the samples so far.

    Nothing is raised from the handler itself: it may run while the FMU's Python code executes on this
    thread, where an exception would escape into pythonfmu (see fmu_bearing/slaves/__init__.py).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def note(signum, frame):
        _Stop.signal = signal.Signals(signum).name

    _Stop.signal = None
    previous = {s: signal.signal(s, note) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _interruptible(observe):
    """``observe`` that raises ``Interrupted`` (caught by the master, samples kept) once a signal was noted."""
    def poll(t):
        if _Stop.signal is not None:
            raise Interrupted(-1, t, f"interrupted by {_Stop.signal}")

    def wrapped(q, qd, qdd, lam, t):
        poll(t)
        return observe(q, qd, qdd, lam, t)
    if hasattr(observe, "probes"):   # the compiled recorder reads the observables; the master polls instead
        wrapped.probes, wrapped.poll = observe.probes, poll
    return wrapped


def _mark_interrupted(result: RunResult) -> RunResult:
    """A run stopped by ``Interrupted`` is "interrupted", not "failed" (a streamed run's table too: the rows it hands
    the output workers carry its status, ``stream.TableStream.tail``)."""
    if _Stop.signal is not None and result.status == "failed":
        t = result.meta.pop("failure", {}).get("time_s")
        result.status = "interrupted"
        result.meta["interrupted"] = {"signal": _Stop.signal, "time_s": t}
        result.message = f"interrupted by {_Stop.signal}" + (f" at t = {t:.9g} s" if t is not None else "")
        if result.streamed is not None:
            result.streamed.stream.mark(result.meta, result.status, result.message)
    return result


def interrupted() -> str | None:
    """The signal (SIGINT, SIGTERM) that stopped the last ``run``, or None."""
    return _Stop.signal


def run(config: RunConfig, sink=None) -> RunResult:
    """Run the slider-crank as configured and return the recorded samples (not yet written).

    SIGINT/SIGTERM during the run (main thread) end it with status "interrupted" and the samples so far.
    ``sink``: a ``mechanism.output.stream.TableStream`` that writes the table as it is recorded (the result is then
    its: some columns and the whole table's figures); the monolithic reference does not stream (its result is whole).
    """
    with stop_on_signals():
        return _mark_interrupted(_run(config, sink))


def _run(config: RunConfig, sink=None) -> RunResult:
    params = SliderCrankParameters(rpm=config.rpm, gravity=config.gravity)
    model = build(params, "ideal" if config.joint == "ideal" else "bearing")
    system = System(model)
    q0, qd0 = initial_state(system, params)
    observe = _interruptible(slider_crank_observer(system))
    t_end = config.revs * config.crank_period
    meta = run_meta(config)
    label = f"{config.joint} {config.mode} {config.rpm:g} rpm"
    settings = MasterSettings(t_end=t_end, step=config.step, output_interval=config.output_interval,
                              scheme=config.scheme, progress=config.progress, description=label)
    if config.joint == "ideal":
        return run_master(system, q0, qd0, settings, observe, reaction_force=ideal_reaction(system), meta=meta,
                          sink=sink)
    link = BearingLink(system, model.bearings[0], config.contact_points)
    if config.mode == "monolithic":
        if config.joint != "bearing":
            raise ValueError("the monolithic reference is implemented for the ball bearing only")
        from mechanism.cosim.monolithic import run_monolithic   # scipy's integrators: imported when used
        bearing = BallBearing(bearing_parameters(config.component_settings))
        meta["contact_stiffness_N_m1.5"] = bearing.stiffness
        return run_monolithic(system, link, bearing, q0, qd0, t_end, config.output_interval, observe,
                              method=config.method, rtol=config.rtol, progress=config.progress, meta=meta)
    if config.mode == "inprocess":
        if config.joint != "bearing":
            raise ValueError("the in-process path is implemented for the ball bearing only")
        endpoint = InProcessEndpoint(bearing_parameters(config.component_settings))
        meta["contact_stiffness_N_m1.5"] = endpoint.bearing.stiffness
    else:
        path = fmu_path(config)
        endpoint = fmu_endpoint(path, config.component_settings, instance_name=config.joint)  # FMI 2 or 3
        meta["fmu"] = str(path)
    if sink is not None and config.joint == "bearing" and not _life_outputs(endpoint):
        # the summary's life then comes from the recorded ball loads, accumulated as they are streamed
        sink.life_params = bearing_parameters(config.component_settings)
    try:
        return run_master(system, q0, qd0, settings, observe, link=link, endpoint=endpoint, meta=meta,
                          energy=energy_account(config, system, link), contact_law=contact_law(config), sink=sink)
    finally:
        endpoint.close()


def _life_outputs(endpoint) -> bool:
    """True if ``endpoint`` will give the bearing's life outputs at the end of the run (the master keeps them): an FMU
    that has the life variables (``fmu_bearing.life.LIFE_NAMES``), or the in-process endpoint."""
    if getattr(endpoint, "life_outputs", None) is None:
        return False
    variables = getattr(endpoint, "variables", None)
    if variables is None:   # the in-process endpoint: its own accumulator
        return True
    from fmu_bearing.life import LIFE_NAMES
    return any(name in variables for name in LIFE_NAMES)


def run_adaptive(config, tol: float, initial_step: float | None = None, **settings) -> RunResult:
    """``run`` with the adaptive communication step (``mechanism.cosim.adaptive``): the slider-crank of ``config`` (a ``RunConfig``, mode
    cosim or inprocess, joint bearing), with ``tol``; extra keyword arguments go to ``AdaptiveSettings``."""
    if config.joint != "bearing" or config.mode not in ("cosim", "inprocess"):
        raise ValueError("the adaptive driver runs the ball-bearing joint in mode cosim or inprocess")
    params = SliderCrankParameters(rpm=config.rpm, gravity=config.gravity)
    model = build(params, "bearing")
    system = System(model)
    q0, qd0 = initial_state(system, params)
    observe = slider_crank_observer(system)
    meta = run_meta(config)
    clearance = meta["clearance_per_side_m"]
    adaptive = AdaptiveSettings(t_end=config.revs * config.crank_period, output_interval=config.output_interval,
                                scheme=config.scheme, progress=config.progress, tol=tol,
                                step=initial_step or min(1e-6, config.output_interval),
                                e_floor=clearance or 1e-5,
                                description=f"adaptive {config.mode} {config.rpm:g} rpm", **settings)
    link = BearingLink(system, model.bearings[0], config.contact_points)
    if config.mode == "inprocess":
        endpoint = InProcessEndpoint(bearing_parameters(config.component_settings))
    else:
        path = fmu_path(config)
        endpoint = fmu_endpoint(path, config.component_settings, instance_name=config.joint)  # FMI 2 or 3
        meta["fmu"] = str(path)
    start = time.perf_counter()
    try:
        result = run_adaptive_master(system, q0, qd0, adaptive, observe, link, endpoint, meta,
                                     energy=energy_account(config, system, link), contact_law=contact_law(config))
    finally:
        endpoint.close()
    result.meta["wall_time_s"] = time.perf_counter() - start
    return result
