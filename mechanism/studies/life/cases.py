"""The life study's operating points and run settings, as data.

The clearance sweep runs at 1200 rpm (the paper's highest speed), from a preload of 15 µm to five times
the paper's 20 µm; the speed sweep runs at the paper's 20 µm from 300 to 1800 rpm.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

#: the paper's radial clearance P_d [m]
PAPER_CLEARANCE = 20e-6
#: clearances of the clearance sweep [m]: preload to five times the paper's 20 µm
CLEARANCES = tuple(c * 1e-6 for c in (-15, -10, -6, -3, 0, 5, 10, 20, 40, 60, 100))
#: crank speeds of the speed sweep [rpm]: the paper's four and beyond
SPEEDS = (300.0, 450.0, 600.0, 900.0, 1200.0, 1500.0, 1800.0)
#: crank speed of the clearance sweep [rpm] (the paper's highest)
CLEARANCE_RPM = 1200.0
#: default step [s]: the paper's and the reproduction's 1e-5 s. 2e-5 s (MAX_STEP, half the cost) gives lives
#: within 0.2 % of 1e-5 s for P_d <= 40 µm at 1200 rpm and at 20 µm and 300 rpm, but 3.5 % apart at 60 µm and
#: 1.7 % at 100 µm, where impacts make the life sensitive (measured); 5e-5 s diverges at 20 µm, and 1e-4 s
#: ran through at -6 µm with a life 5e4 times too short, so steps above MAX_STEP are refused
DEFAULT_STEP = 1e-5
MAX_STEP = 2e-5
#: the figures of a point without a life (a failed run)
NAN_FIGURES = dict(equivalent_load_inner_N=math.nan, equivalent_load_outer_N=math.nan, rating_life_Mrev=math.nan,
                    rating_life_h=math.nan, max_ball_load_N=math.nan)


@dataclass(frozen=True)
class Point:
    """One operating point: which sweep, crank speed [rpm], radial clearance P_d [m]."""

    sweep: str
    rpm: float
    radial_clearance: float


@dataclass(frozen=True)
class Settings:
    """Run settings shared by every point (SI)."""

    startup_revs: float = 1.0
    window_revs: float = 1.0
    step: float = DEFAULT_STEP
    balls: int = 8


def points(clearances=CLEARANCES, speeds=SPEEDS, clearance_rpm=CLEARANCE_RPM) -> list[Point]:
    """The clearance sweep at ``clearance_rpm`` and the speed sweep at the paper's clearance."""
    return ([Point("clearance", clearance_rpm, c) for c in clearances]
            + [Point("speed", rpm, PAPER_CLEARANCE) for rpm in speeds])
