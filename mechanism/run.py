"""The one driver: a run's configuration -> the system -> the master (or the monolithic reference) -> a RunResult.

``RunConfig`` is what the command line ``python -m mechanism run`` (and ``--ssp``, and every study)
fills in; ``run`` builds the paper's slider-crank (``mechanism.systems.slider_crank``) on the generic
multibody core (``mechanism.multibody``), the bearing link and component (``mechanism.cosim``), and
hands them to the fixed-step master, the adaptive master (``run_adaptive``) or the monolithic
reference. Writing files is ``mechanism.output``'s job.
"""
from __future__ import annotations

import argparse
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import from_values as bearing_parameters
from mechanism.cosim.adaptive import AdaptiveSettings
from mechanism.cosim.adaptive import run_adaptive as run_adaptive_master
from mechanism.cosim.coupling import DEFAULT_SCHEME
from mechanism.cosim.energy import EnergyAccount
from mechanism.cosim.endpoints import FmuEndpoint, InProcessEndpoint
from mechanism.cosim.joint import BearingLink
from mechanism.cosim.master import MasterSettings, run_master
from mechanism.cosim.monolithic import run_monolithic
from mechanism.cosim.record import RunResult
from mechanism.multibody.solver import System
from mechanism.systems.slider_crank import (SliderCrankParameters, build, ideal_reaction, initial_state,
                                            slider_crank_observer)

JOINTS = ("bearing", "ideal", "clearance")
MODES = ("cosim", "inprocess", "monolithic")
FMU_NAMES = {"bearing": "BallBearing", "clearance": "JournalClearance"}


@dataclass
class RunConfig:
    """Everything that defines a run (SI, except rpm). ``settings`` are start values for the bearing component."""

    rpm: float = 1200.0
    revs: float = 2.0
    balls: int | None = None
    joint: str = "bearing"
    mode: str = "cosim"
    step: float = 1e-5
    output_interval: float = 1e-5
    settings: dict = field(default_factory=dict)
    scheme: str = DEFAULT_SCHEME
    contact_points: str = "centres"
    gravity: bool = False
    fmu: str | None = None
    method: str = "LSODA"
    rtol: float = 1e-9
    progress: bool = True

    def __post_init__(self):
        if self.joint not in JOINTS:
            raise ValueError(f"joint must be one of {JOINTS}, not {self.joint!r}")
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, not {self.mode!r}")
        if not (self.step > 0 and self.output_interval > 0 and self.revs > 0 and self.rpm > 0):
            raise ValueError("rpm, revs, step and output_interval must be positive")

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


def energy_account(config: RunConfig, system: System, link: BearingLink) -> EnergyAccount | None:
    """The run's energy account (``mechanism.cosim.energy``): the ball bearing's law in-process; None for
    the journal-clearance joint (its account is not implemented)."""
    if config.joint != "bearing":
        return None
    return EnergyAccount(system, link, BallBearing(bearing_parameters(config.component_settings)))


def run(config: RunConfig) -> RunResult:
    """Run the slider-crank as configured and return the recorded samples (not yet written)."""
    params = SliderCrankParameters(rpm=config.rpm, gravity=config.gravity)
    model = build(params, "ideal" if config.joint == "ideal" else "bearing")
    system = System(model)
    q0, qd0 = initial_state(system, params)
    observe = slider_crank_observer(system)
    t_end = config.revs * config.crank_period
    meta = {"config": asdict(config), "crank_period_s": config.crank_period,
            "clearance_per_side_m": clearance_per_side(config)}
    label = f"{config.joint} {config.mode} {config.rpm:g} rpm"
    settings = MasterSettings(t_end=t_end, step=config.step, output_interval=config.output_interval,
                              scheme=config.scheme, progress=config.progress, description=label)
    if config.joint == "ideal":
        return run_master(system, q0, qd0, settings, observe, reaction_force=ideal_reaction(system), meta=meta)
    link = BearingLink(system, model.bearings[0], config.contact_points)
    if config.mode == "monolithic":
        if config.joint != "bearing":
            raise ValueError("the monolithic reference is implemented for the ball bearing only")
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
        endpoint = FmuEndpoint(path, config.component_settings, instance_name=config.joint)
        meta["fmu"] = str(path)
    try:
        return run_master(system, q0, qd0, settings, observe, link=link, endpoint=endpoint, meta=meta,
                          energy=energy_account(config, system, link))
    finally:
        endpoint.close()


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
    clearance = clearance_per_side(config)
    meta = {"config": asdict(config), "crank_period_s": config.crank_period, "clearance_per_side_m": clearance}
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
        endpoint = FmuEndpoint(path, config.component_settings, instance_name=config.joint)
        meta["fmu"] = str(path)
    start = time.perf_counter()
    try:
        result = run_adaptive_master(system, q0, qd0, adaptive, observe, link, endpoint, meta,
                                     energy=energy_account(config, system, link))
    finally:
        endpoint.close()
    result.meta["wall_time_s"] = time.perf_counter() - start
    return result
