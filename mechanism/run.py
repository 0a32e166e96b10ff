"""One run of the paper's slider-crank: which joint, which mode, which component; writes the result files.

``RunConfig`` is what the command line ``python -m mechanism run`` fills in; ``run`` builds the
model (``slider_crank``), the generic system (``solver``), the bearing link and component,
and hands them to the master (``master``) or to the monolithic reference (``monolithic``).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from fmu_bearing.ball_bearing import BallBearing
from .bearing_joint import BearingLink
from .coupling import DEFAULT_SCHEME
from .exchange import FmuEndpoint, InProcessEndpoint, bearing_parameters
from .master import MasterSettings, run_master
from .monolithic import run_monolithic
from .results import RunResult, summary, write_csv
from .slider_crank import SliderCrankParameters, build, initial_state
from .solver import System

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


def slider_crank_observer(system: System):
    """observe(q, qd, qdd, lam, t): crank angle, slider position/velocity/acceleration, crank moment (SI)."""
    crank, slider = system.slice("crank"), system.slice("slider")

    def observe(q, qd, qdd, lam, t):
        return {"crank_angle": float(q[crank.start + 2]), "slider_x": float(q[slider.start]),
                "slider_v": float(qd[slider.start]), "slider_a": float(qdd[slider.start]),
                "crank_moment": system.driving_moment(lam, "crank_driver")}
    return observe


def ideal_reaction(system: System):
    """The ideal crank-rod pin's force on the crank (the housing body) from eq. (7), as (F_x, F_y) [N]."""
    crank = system.slice("crank")

    def reaction(q, lam):
        Qc = system.reactions(q, lam)["crank_rod"]
        return float(Qc[crank.start]), float(Qc[crank.start + 1])
    return reaction


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
        return run_master(system, q0, qd0, settings, observe, link=link, endpoint=endpoint, meta=meta)
    finally:
        endpoint.close()


def write_outputs(result: RunResult, out: Path, ideal: RunResult | None = None, plots: bool = True) -> dict:
    """timeseries.csv, summary.json (with the ideal joint's figures if given) and the PNG plots into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(result, out / "timeseries.csv")
    figures = summary(result)
    if ideal is not None:
        write_csv(ideal, out / "ideal_timeseries.csv")
        figures["ideal"] = summary(ideal)
        if len(result["time"]) and len(ideal["time"]) >= len(result["time"]):
            k = len(result["time"])
            figures["rms_slider_acceleration_deviation_m_s2"] = float(
                np.sqrt(np.mean((result["slider_a"] - ideal["slider_a"][:k]) ** 2)))
            figures["max_slider_position_error_m"] = float(np.max(np.abs(result["slider_x"] - ideal["slider_x"][:k])))
    (out / "summary.json").write_text(json.dumps(figures, indent=2, default=float) + "\n")
    if plots and len(result["time"]) > 1:
        from .plots import plot_run
        plot_run(result, out, ideal)
    return figures
