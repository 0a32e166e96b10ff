"""The reproduction's operating points as data: the paper's speeds, ball counts, the ideal-joint step, the
"paper units" stiffness variant, and the list of runs (``run_specs``)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import BearingParameters
from mechanism.run import RunConfig



#: the paper's crank speeds [rpm] and ball counts (Section 5)
SPEEDS = (300.0, 600.0, 900.0, 1200.0)
BALL_COUNTS = (8, 15, 20)
#: speed of the ball-count study and of the clearance-joint comparison [rpm]
STUDY_RPM = 1200.0
#: communication step (= output interval) of the ideal-joint runs [s]: no contact, so the step is set by the
#: mechanism alone; RK4 at 1e-4 s matches 1e-5 s to < 1e-9 (relative, at common samples, 1200 rpm, measured),
#: and the cubic splines through its samples with which the report compares it with the contact runs (sampled
#: every 1e-5 s) are within 4e-9 of the 1e-5 s run (relative; slider position within 1e-10 m); it saves a
#: quarter of the reproduction's run time (tests/test_reproduce_trends.py checks both)
IDEAL_STEP = 1e-4
#: the paper-units stiffness variant: K in N/mm^1.5 used as if it were N/m^1.5 is 1000x too soft
PAPER_STIFFNESS_DIVISOR = 1000.0
#: the paper variant's eccentricity guard, as a fraction of the ball diameter (its deflections are ~1 mm)
PAPER_ECCENTRICITY_LIMIT_FRACTION = 0.5

@dataclass(frozen=True)
class RunSpec:
    """One run of the reproduction: a unique ``name``, its group and the configuration."""

    name: str
    group: str      # "bearing", "ideal", "balls", "clearance", "paper-K"
    label: str
    config: RunConfig = field(compare=False)


# --- the run list -------------------------------------------------------------------------------
def balls_fit(n_balls: int, params: BearingParameters | None = None) -> bool:
    """n_balls balls of diameter D fit on the pitch circle d_m (neighbour chord > D)."""
    p = params or BearingParameters()
    return p.pitch_diameter * math.sin(math.pi / n_balls) > p.ball_diameter


def paper_stiffness() -> float:
    """K / 1000 [N/m^1.5]: the Hertz constant of Table 2 (f = 0.52) as a kg-mm-s code would use it."""
    return BallBearing().stiffness / PAPER_STIFFNESS_DIVISOR


def paper_settings() -> dict:
    """FMU start values of the paper-units stiffness variant (K/1000 and a wider divergence guard)."""
    p = BearingParameters()
    return {"contact_stiffness": paper_stiffness(),
            "eccentricity_limit": PAPER_ECCENTRICITY_LIMIT_FRACTION * p.ball_diameter}


def run_specs(revs: float = 2.0, step: float = 1e-5, output_interval: float = 1e-5,
              ideal_step: float = IDEAL_STEP) -> list[RunSpec]:
    """The full run list of the reproduction (see the module docstring)."""
    base = dict(revs=revs, step=step, output_interval=output_interval, mode="cosim", progress=False)
    ideal_base = dict(base, step=ideal_step, output_interval=max(ideal_step, output_interval))
    specs = []
    for rpm in SPEEDS:
        specs.append(RunSpec(f"bearing-{rpm:g}", "bearing", f"ball bearing, 8 balls, {rpm:g} rpm",
                             RunConfig(rpm=rpm, balls=8, joint="bearing", **base)))
        specs.append(RunSpec(f"ideal-{rpm:g}", "ideal", f"ideal joint, {rpm:g} rpm",
                             RunConfig(rpm=rpm, joint="ideal", **ideal_base)))
    for n in BALL_COUNTS:
        if n == 8:
            continue  # bearing-1200
        settings = {} if balls_fit(n) else {"allow_ball_overlap": True}
        specs.append(RunSpec(f"bearing-{STUDY_RPM:g}-{n}balls", "balls",
                             f"ball bearing, {n} balls{' (overlapping, hypothetical)' if settings else ''}, "
                             f"{STUDY_RPM:g} rpm",
                             RunConfig(rpm=STUDY_RPM, balls=n, joint="bearing", settings=settings, **base)))
    specs.append(RunSpec(f"clearance-{STUDY_RPM:g}", "clearance", f"journal-bushing clearance joint, {STUDY_RPM:g} rpm",
                         RunConfig(rpm=STUDY_RPM, joint="clearance", **base)))
    for rpm in SPEEDS:
        specs.append(RunSpec(f"paperK-{rpm:g}", "paper-K", f"ball bearing, 8 balls, K/1000 (paper units), {rpm:g} rpm",
                             RunConfig(rpm=rpm, balls=8, joint="bearing", settings=paper_settings(), **base)))
    return specs


def ideal_name(spec_or_rpm) -> str:
    """Name of the ideal-joint counterpart of a run (the ideal run at the same speed)."""
    rpm = spec_or_rpm.config.rpm if isinstance(spec_or_rpm, RunSpec) else float(spec_or_rpm)
    return f"ideal-{rpm:g}"


# --- cache ----------------------------------------------------------------------------------------
