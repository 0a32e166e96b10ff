"""Bearing parameters (SI) with the defaults of the paper's Table 2 (SKF BB1B420205), and their validation.

Every parameter of the BallBearing FMU is a field here; the FMU, the master, the SSP
parameter sets and the tests all take their defaults from this one place.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace

#: damping_model values
DAMPING_NONE, DAMPING_CONSTANT, DAMPING_OIL_FILM = 0, 1, 2

#: tolerance on d_i = d_m - D and d_o = d_m + D, as a fraction of the ball diameter
RACEWAY_TOLERANCE = 0.01
#: most negative radial clearance (preload) accepted, as a fraction of the ball diameter: P_d >= -1 % D
#: (a preload deflection of 0.5 % D per ball, about 3 kN per ball for Table 2, far beyond any fit)
MAX_PRELOAD_FRACTION = 0.01


class BearingParameterError(ValueError):
    """An invalid bearing parameter; ``name`` and ``value`` say which."""

    def __init__(self, name: str, value, reason: str):
        super().__init__(f"invalid parameter {name} = {value!r}: {reason}")
        self.name, self.value, self.reason = name, value, reason


def _param(default, unit: str, description: str):
    """A parameter field with its SI unit ("" for integers, "1" for dimensionless reals) and description.

    The BallBearing FMU declares its parameters, units and descriptions from this metadata.
    """
    return field(default=default, metadata={"unit": unit, "description": description})


@dataclass(frozen=True)
class BearingParameters:
    """Geometry, material, damping and lubricant of a deep-groove ball bearing (SI units).

    Defaults: Table 2 of Xu et al. (2012), SKF BB1B420205; groove conformities, damping
    and lubricant are not in the paper (see docs/modelling-choices.md).
    """

    n_balls: int = _param(8, "", "number of balls N_b (at most the FMU's per-ball output capacity)")
    ball_diameter: float = _param(8.7e-3, "m", "ball diameter D")
    pitch_diameter: float = _param(37.9e-3, "m", "pitch diameter d_m")
    inner_race_diameter: float = _param(29.2e-3, "m", "inner raceway diameter d_i (= d_m - D within 1 % of D)")
    outer_race_diameter: float = _param(46.6e-3, "m", "outer raceway diameter d_o (= d_m + D within 1 % of D)")
    bore_diameter: float = _param(24e-3, "m", "bore diameter (catalogue data, informative)")
    outside_diameter: float = _param(52e-3, "m", "outside diameter (catalogue data, informative)")
    radial_clearance: float = _param(0.02e-3, "m", "radial (diametral) internal clearance P_d; "
                                     "negative = preload (at least -1 % of ball_diameter)")
    youngs_modulus: float = _param(207e9, "Pa", "Young's modulus E of balls and rings")
    poisson_ratio: float = _param(0.3, "1", "Poisson's ratio nu of balls and rings, in (0, 0.5)")
    inner_groove_conformity: float = _param(0.52, "1", "inner groove radius / ball diameter f_i (> 0.5)")
    outer_groove_conformity: float = _param(0.52, "1", "outer groove radius / ball diameter f_o (> 0.5)")
    damping_model: int = _param(DAMPING_CONSTANT, "", "0 none, 1 constant damping_coefficient, 2 oil film (eq. 29-32)")
    damping_coefficient: float = _param(50.0, "N.s/m", "damping coefficient C per loaded ball (damping_model 1)")
    oil_viscosity: float = _param(0.04, "Pa.s", "absolute oil viscosity eta (damping_model 2; ISO VG 46 near 40 C)")
    pressure_viscosity_coefficient: float = _param(2.0e-8, "1/Pa", "pressure-viscosity coefficient alpha (damping_model 2)")
    min_film_thickness: float = _param(0.1e-6, "m", "floor of the film thickness h_0, composite roughness (damping_model 2)")
    cage_angle_start: float = _param(0.0, "rad", "angle of ball 1 at the start time")
    contact_stiffness: float = _param(0.0, "N/m1.5", "ball load-deflection constant K override; 0 = computed from geometry (Hertz)")
    eccentricity_limit: float = _param(0.0, "m", "|e| beyond this is divergence (error); 0 = 5 % of ball_diameter")
    allow_ball_overlap: bool = _param(False, "", "accept ball counts that do not fit on the pitch circle "
                                              "(the paper's hypothetical 15- and 20-ball studies)")
    reliability_factor: float = _param(1.0, "1", "life modification factor a1 for reliability (ISO 281 "
                                               "Table 12): 1 = 90 %, 0.64 = 95 %, 0.25 = 99 %; in (0, 1]")

    def replace(self, **changes) -> "BearingParameters":
        return replace(self, **changes)

    def as_dict(self) -> dict:
        return asdict(self)

    @property
    def effective_eccentricity_limit(self) -> float:
        """|e| limit [m]: ``eccentricity_limit`` or, if 0, 5 % of the ball diameter (0.435 mm for Table 2)."""
        return self.eccentricity_limit if self.eccentricity_limit > 0 else 0.05 * self.ball_diameter


#: documented physical range [min, max] of each number (SI; docs/robustness.md), far beyond any real ball
#: bearing, so that only absurd values (a stiffness of 1e300) are refused; poisson_ratio's (0, 0.5) and the
#: preload limit of radial_clearance are checked in ``validate`` with their reasons.
RANGES = {
    "n_balls": (3, 1000),
    "ball_diameter": (1e-4, 1.0),
    "pitch_diameter": (1e-4, 10.0),
    "inner_race_diameter": (0.0, 10.0),
    "outer_race_diameter": (1e-4, 10.0),
    "bore_diameter": (0.0, 10.0),
    "outside_diameter": (0.0, 10.0),
    "radial_clearance": (-1e-2, 1e-2),              # preload: at most MAX_PRELOAD_FRACTION of D, below
    "youngs_modulus": (1e6, 1e13),
    "inner_groove_conformity": (-math.inf, 10.0),     # > 0.5: checked below with its reason
    "outer_groove_conformity": (-math.inf, 10.0),
    "damping_model": (0, 2),
    "damping_coefficient": (0.0, 1e8),
    "oil_viscosity": (0.0, 1e3),
    "pressure_viscosity_coefficient": (0.0, 1e-6),
    "min_film_thickness": (0.0, 1e-3),
    "cage_angle_start": (-1e6, 1e6),
    "contact_stiffness": (0.0, 1e14),
    "eccentricity_limit": (0.0, 1.0),
}


def validate(p: BearingParameters, capacity: int | None = None) -> None:
    """Raise BearingParameterError naming the first invalid parameter of ``p``.

    ``capacity`` is the number of per-ball outputs of a built FMU (n_balls may not exceed it).
    """
    for f in fields(p):
        v = getattr(p, f.name)
        if isinstance(v, float) and not math.isfinite(v):
            raise BearingParameterError(f.name, v, "must be a finite number")
        if f.type in ("int", int) and (isinstance(v, bool) or not isinstance(v, int)):
            raise BearingParameterError(f.name, v, "must be an integer")
        lo, hi = RANGES.get(f.name, (-math.inf, math.inf))
        if not isinstance(v, bool) and not lo <= v <= hi:
            unit = f.metadata.get("unit", "").strip("1")
            raise BearingParameterError(f.name, v, f"outside its range [{lo:g}, {hi:g}] {unit}".rstrip())
    if p.n_balls < 3:
        raise BearingParameterError("n_balls", p.n_balls, "a ball bearing needs at least 3 balls")
    if capacity is not None and p.n_balls > capacity:
        raise BearingParameterError("n_balls", p.n_balls,
                                    f"exceeds the FMU's capacity of {capacity} balls (build one with "
                                    f"`python build_fmu.py --max-balls {p.n_balls}` and pass it with --fmu)")
    for name in ("ball_diameter", "pitch_diameter"):
        if getattr(p, name) <= 0:
            raise BearingParameterError(name, getattr(p, name), "must be positive")
    D, dm = p.ball_diameter, p.pitch_diameter
    if D >= dm:
        raise BearingParameterError("ball_diameter", D, f"must be smaller than pitch_diameter = {dm!r}")
    # Balls fit on the pitch circle when the chord between neighbours exceeds D.
    chord = dm * math.sin(math.pi / p.n_balls)
    if chord <= D and not p.allow_ball_overlap:
        raise BearingParameterError(
            "n_balls", p.n_balls,
            f"{p.n_balls} balls of diameter {D} m do not fit on a pitch circle of diameter {dm} m "
            f"(neighbour spacing {chord:.6g} m); set allow_ball_overlap for a hypothetical ball count "
            f"such as the paper's 15- and 20-ball studies")
    tol = RACEWAY_TOLERANCE * D
    if abs(p.inner_race_diameter - (dm - D)) > tol:
        raise BearingParameterError("inner_race_diameter", p.inner_race_diameter,
                                    f"inconsistent with pitch_diameter - ball_diameter = {dm - D:.6g} m")
    if abs(p.outer_race_diameter - (dm + D)) > tol:
        raise BearingParameterError("outer_race_diameter", p.outer_race_diameter,
                                    f"inconsistent with pitch_diameter + ball_diameter = {dm + D:.6g} m")
    if p.radial_clearance < -MAX_PRELOAD_FRACTION * D:  # negative clearance = preload (docs/bearing-life.md)
        raise BearingParameterError("radial_clearance", p.radial_clearance,
                                    f"a preload beyond -{MAX_PRELOAD_FRACTION:g} x ball_diameter = "
                                    f"{-MAX_PRELOAD_FRACTION * D:.6g} m is outside the model's range")
    if p.youngs_modulus <= 0:
        raise BearingParameterError("youngs_modulus", p.youngs_modulus, "must be positive")
    if not 0.0 < p.poisson_ratio < 0.5:
        raise BearingParameterError("poisson_ratio", p.poisson_ratio, "must lie in (0, 0.5)")
    for name in ("inner_groove_conformity", "outer_groove_conformity"):
        if getattr(p, name) <= 0.5:
            raise BearingParameterError(name, getattr(p, name),
                                        "must exceed 0.5 (the groove radius must exceed the ball radius)")
    if not 0.0 < p.reliability_factor <= 1.0:
        raise BearingParameterError("reliability_factor", p.reliability_factor, "must lie in (0, 1] (ISO 281 a1)")
    if p.damping_model not in (DAMPING_NONE, DAMPING_CONSTANT, DAMPING_OIL_FILM):
        raise BearingParameterError("damping_model", p.damping_model, "must be 0 (none), 1 (constant) or 2 (oil film)")
    for name in ("damping_coefficient", "oil_viscosity", "pressure_viscosity_coefficient",
                 "min_film_thickness", "contact_stiffness", "eccentricity_limit"):
        if getattr(p, name) < 0:
            raise BearingParameterError(name, getattr(p, name), "must not be negative")
    if p.damping_model == DAMPING_OIL_FILM:
        for name in ("oil_viscosity", "pressure_viscosity_coefficient", "min_film_thickness"):
            if getattr(p, name) <= 0:
                raise BearingParameterError(name, getattr(p, name), "must be positive for the oil-film damping model")
    if p.effective_eccentricity_limit <= max(p.radial_clearance, 0.0) / 2:  # preload: any positive limit
        raise BearingParameterError("eccentricity_limit", p.eccentricity_limit,
                                    "must exceed half the radial clearance")


def from_values(values) -> BearingParameters:
    """BearingParameters from user input, name -> value: the one place where user input
    (``--set NAME=VALUE``, ``.ssv`` parameter sets, study options) becomes parameters.

    Each value is converted to its field's type; an unknown name, an integer field given a
    non-integer (``n_balls = 7.9``) or a Boolean field given anything but a Boolean or 0/1 is an
    error naming the parameter. Ranges are checked by ``validate``.
    """
    kinds = {f.name: type(f.default) for f in fields(BearingParameters)}
    unknown = sorted(set(values) - set(kinds))
    if unknown:
        raise BearingParameterError(unknown[0], values[unknown[0]],
                                    f"not a BallBearing parameter (known: {', '.join(kinds)})")
    return BearingParameters(**{k: _convert(k, kinds[k], v) for k, v in values.items()})


def _convert(name: str, kind: type, value):
    """``value`` as ``kind`` (int, float or bool), refusing a conversion that would change it."""
    if kind is bool:
        if isinstance(value, bool) or value in (0, 1):
            return bool(value)
        raise BearingParameterError(name, value, "must be true or false")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise BearingParameterError(name, value, "must be a number") from None
    if kind is int:
        if not number.is_integer():
            raise BearingParameterError(name, value, "must be an integer")
        return int(number)
    return number
