"""Bearing rating life from per-ball loads: ISO 281 load rating and ISO/TS 16281 reference rating life.

Standard library only (the FMU runtime needs nothing else). SI units throughout: lengths in m,
loads in N, angular velocities in rad/s, time in s. The empirical rating formulas of ISO 281 and
ISO/TS 16281 are written in N and mm; ``_MM`` converts lengths to mm at their edge only, and their
results are in N. The method, the symbols and the limits are in docs/bearing-life.md.

* ``dynamic_load_rating``: basic dynamic radial load rating C_r of a single-row deep-groove ball
  bearing, ISO 281:2007 clause 5.1 with the f_c table (Table 2) and b_m = 1.3 (Table 1).
* ``raceway_load_ratings``: basic dynamic load ratings Q_ci, Q_ce of the inner and outer raceway
  contacts, ISO/TS 16281:2008 (Lundberg-Palmgren, ISO/TR 1281-1 background), with b_m.
* ``LifeAccumulator``: equivalent rolling-element loads Q_ei, Q_ee of a simulated load history and
  the reference rating life L10r = a1 [(Q_ci/Q_ei)^(-10/3) + (Q_ce/Q_ee)^(-10/3)]^(-9/10).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

#: m -> mm, applied only at the edge of the empirical N/mm formulas of ISO 281 and ISO/TS 16281
_MM = 1e3
#: rating factor b_m for radial ball bearings of contemporary steel, ISO 281:2007 Table 1
B_M_RADIAL_BALL = 1.3
#: ISO 281:2007 Table 2, column "single-row radial contact groove ball bearings": f_c at
#: D_w cos(alpha) / D_pw = 0.01, 0.02, ..., 0.40 (linear interpolation between rows, as the standard says)
F_C_TABLE = (29.1, 35.8, 40.3, 43.8, 46.7, 49.1, 51.1, 52.8, 54.3, 55.5,
             56.6, 57.5, 58.2, 58.8, 59.3, 59.6, 59.8, 59.9, 60.0, 59.9,
             59.8, 59.6, 59.3, 59.0, 58.6, 58.2, 57.7, 57.1, 56.6, 56.0,
             55.3, 54.6, 53.9, 53.2, 52.4, 51.7, 50.9, 50.0, 49.2, 48.4)
#: life exponent p of point contact (ISO 281:2007 clause 5.3: L10 = (C/P)^3); also the exponent of the
#: rotating ring's equivalent load and of the Palmgren-Miner time average (ISO/TS 16281)
P_BALL = 3.0
#: exponent of the stationary ring's equivalent load, p e = 3 x 10/9 (ISO/TS 16281; Weibull e = 10/9)
P_STATIONARY = 10.0 / 3.0
#: seconds per hour
HOUR = 3600.0
#: 2 pi and p / p e, computed once (the same doubles as written out in LifeAccumulator.add)
_TWO_PI = 2.0 * math.pi
_CUBE_OF_STATIONARY = P_BALL / P_STATIONARY


#: outputs of the BallBearing FMU (and of the in-process endpoint) from the ratings, computed from the
#: parameters at initialisation: (name, unit, description, LoadRatings field)
RATING_OUTPUTS = (
    ("dynamic_load_rating", "N", "basic dynamic radial load rating C_r (ISO 281 clause 5.1, b_m = 1.3), from the "
                                 "geometry at initialisation", "C_r"),
    ("raceway_rating_inner", "N", "basic dynamic load rating Q_ci of the inner raceway contact (ISO/TS 16281)", "Q_ci"),
    ("raceway_rating_outer", "N", "basic dynamic load rating Q_ce of the outer raceway contact (ISO/TS 16281)", "Q_ce"),
)
#: outputs accumulated over the simulated time (docs/bearing-life.md): (name, unit, description, LifeAccumulator property)
LIFE_OUTPUTS = (
    ("equivalent_load_inner", "N", "equivalent rolling-element load Q_ei of the inner ring over the simulated "
                                   "history (ISO/TS 16281); 0 before any ball is loaded", "equivalent_load_inner"),
    ("equivalent_load_outer", "N", "equivalent rolling-element load Q_ee of the outer ring over the simulated "
                                   "history (ISO/TS 16281); 0 before any ball is loaded", "equivalent_load_outer"),
    ("rating_life", "h", "reference rating life L10r (x reliability_factor) at the mean relative ring speed of "
                         "the simulated history; +inf (infinite life) before any ball is loaded", "life_hours"),
    ("rating_life_revolutions", "Mrev", "reference rating life L10r (x reliability_factor) in millions of "
                                        "revolutions of one ring relative to the other; +inf before any ball is "
                                        "loaded", "life_revolutions"),
)


#: names of RATING_OUTPUTS then LIFE_OUTPUTS
LIFE_NAMES = tuple(name for name, _, _, _ in RATING_OUTPUTS + LIFE_OUTPUTS)


def output_values(acc: "LifeAccumulator") -> list[float]:
    """The values of RATING_OUTPUTS then LIFE_OUTPUTS for ``acc``."""
    return ([float(getattr(acc.ratings, field)) for _, _, _, field in RATING_OUTPUTS]
            + [float(getattr(acc, prop)) for _, _, _, prop in LIFE_OUTPUTS])


class LifeInputError(ValueError):
    """Inputs the life calculation cannot accept (geometry out of the standard's range, bad loads)."""


def f_c_factor(gamma: float) -> float:
    """f_c of ISO 281:2007 Table 2 at gamma = D_w cos(alpha)/D_pw, linearly interpolated (N, mm units)."""
    if not 0.01 <= gamma <= 0.40:
        raise LifeInputError(f"D_w cos(alpha)/D_pw = {gamma!r} lies outside ISO 281 Table 2 (0.01 to 0.40)")
    x = (gamma - 0.01) / 0.01
    k = min(int(x), len(F_C_TABLE) - 2)
    return F_C_TABLE[k] + (x - k) * (F_C_TABLE[k + 1] - F_C_TABLE[k])


def dynamic_load_rating(ball_diameter: float, pitch_diameter: float, n_balls: int,
                        rows: int = 1, contact_angle: float = 0.0, b_m: float = B_M_RADIAL_BALL) -> float:
    """Basic dynamic radial load rating C_r [N] of a radial ball bearing, ISO 281:2007 clause 5.1.

    D_w <= 25.4 mm: C_r = b_m f_c (i cos alpha)^0.7 Z^(2/3) D_w^1.8          # ISO 281 5.1, D_w <= 25.4 mm
    D_w >  25.4 mm: C_r = 3.647 b_m f_c (i cos alpha)^0.7 Z^(2/3) D_w^1.4    # ISO 281 5.1, D_w > 25.4 mm
    with D_w in mm and C_r in N (the standard's units; converted here).
    """
    D = ball_diameter * _MM
    gamma = ball_diameter * math.cos(contact_angle) / pitch_diameter
    base = b_m * f_c_factor(gamma) * (rows * math.cos(contact_angle)) ** 0.7 * n_balls ** (2.0 / 3.0)
    return base * D ** 1.8 if D <= 25.4 else 3.647 * base * D ** 1.4


def raceway_load_ratings(ball_diameter: float, pitch_diameter: float, n_balls: int,
                         inner_conformity: float, outer_conformity: float,
                         contact_angle: float = 0.0, b_m: float = B_M_RADIAL_BALL) -> tuple[float, float]:
    """Basic dynamic load ratings (Q_ci, Q_ce) [N] of the inner and outer raceway contacts (point contact).

    ISO/TS 16281:2008 (Lundberg-Palmgren; ISO/TR 1281-1), D_w in mm, Q in N, r = f D_w the groove radius:
      Q_ci = b_m 98.1 (2f_i/(2f_i - 1))^0.41 (1 - gamma)^1.39 / (1 + gamma)^(1/3) (gamma/cos a)^0.3 D_w^1.8 Z^(-1/3)
      Q_ce = b_m 98.1 (2f_e/(2f_e - 1))^0.41 (1 + gamma)^1.39 / (1 - gamma)^(1/3) (gamma/cos a)^0.3 D_w^1.8 Z^(-1/3)
    with gamma = D_w cos(alpha)/D_pw. b_m (ISO 281 Table 1) raises the ratings of 1962 steel to today's,
    as it does for C_r; docs/bearing-life.md compares the result with C_r.
    """
    for name, f in (("inner_conformity", inner_conformity), ("outer_conformity", outer_conformity)):
        if not f > 0.5:
            raise LifeInputError(f"{name} = {f!r} must exceed 0.5")
    D = ball_diameter * _MM
    gamma = ball_diameter * math.cos(contact_angle) / pitch_diameter
    if not 0.0 < gamma < 1.0:
        raise LifeInputError(f"gamma = D_w cos(alpha)/D_pw = {gamma!r} must lie in (0, 1)")
    common = b_m * 98.1 * (gamma / math.cos(contact_angle)) ** 0.3 * D ** 1.8 * n_balls ** (-1.0 / 3.0)
    q_ci = common * (2 * inner_conformity / (2 * inner_conformity - 1)) ** 0.41 \
        * (1 - gamma) ** 1.39 / (1 + gamma) ** (1.0 / 3.0)          # ISO/TS 16281 Q_ci
    q_ce = common * (2 * outer_conformity / (2 * outer_conformity - 1)) ** 0.41 \
        * (1 + gamma) ** 1.39 / (1 - gamma) ** (1.0 / 3.0)          # ISO/TS 16281 Q_ce
    return q_ci, q_ce


@dataclass(frozen=True)
class LoadRatings:
    """Load ratings of one single-row deep-groove ball bearing (contact angle 0), all in N.

    C_r: basic dynamic radial load rating (ISO 281 clause 5.1); Q_ci, Q_ce: basic dynamic load ratings of the
    inner and outer raceway contacts (ISO/TS 16281); n_balls: Z; gamma = D/D_pw [-].
    """

    C_r: float
    Q_ci: float
    Q_ce: float
    n_balls: int
    gamma: float

    @classmethod
    def of(cls, ball_diameter: float, pitch_diameter: float, n_balls: int,
           inner_conformity: float, outer_conformity: float) -> "LoadRatings":
        """Ratings from the geometry (m): D, D_pw, Z, groove conformities f_i, f_e."""
        q_ci, q_ce = raceway_load_ratings(ball_diameter, pitch_diameter, n_balls, inner_conformity, outer_conformity)
        return cls(dynamic_load_rating(ball_diameter, pitch_diameter, n_balls), q_ci, q_ce, int(n_balls),
                   ball_diameter / pitch_diameter)

    @classmethod
    def of_bearing(cls, params) -> "LoadRatings":
        """Ratings of a ``fmu_bearing.parameters.BearingParameters``."""
        return cls.of(params.ball_diameter, params.pitch_diameter, int(params.n_balls),
                      params.inner_groove_conformity, params.outer_groove_conformity)


def rating_life(q_ci: float, q_ce: float, q_ei: float, q_ee: float, reliability_factor: float = 1.0) -> float:
    """L10r [millions of revolutions] = a1 [(Q_ci/Q_ei)^(-10/3) + (Q_ce/Q_ee)^(-10/3)]^(-9/10).

    ISO/TS 16281:2008 (reference rating life of a point-contact bearing, one lamina; a1 of ISO 281
    Table 12 multiplies it). Infinite when neither ring carries load (Q_ei = Q_ee = 0).
    """
    damage = (q_ei / q_ci) ** P_STATIONARY + (q_ee / q_ce) ** P_STATIONARY
    return math.inf if damage == 0.0 else reliability_factor * damage ** -0.9


class LifeAccumulator:
    """Equivalent rolling-element loads and L10r accumulated over a simulated load history.

    Each call of ``add`` adds one time step dt with the per-ball loads Q_j (N) and the ring speeds held.
    Per step (ISO/TS 16281, point contact):
      ring rotating relative to the load:   Q_e,k = (1/Z sum_j Q_j^3)^(1/3)        (cubic mean)
      ring stationary relative to the load: Q_e,k = (1/Z sum_j Q_j^(10/3))^(3/10)  ((10/3)-power mean)
    The ring rotating relative to the load is the one with the larger |omega_ring - omega_load|
    (omega_load: angular velocity of the load direction; 0 = load fixed in the global frame).
    Over time, Palmgren-Miner with the life exponent 3, weighted by the revolutions Delta n_k =
    |omega_inner - omega_outer| dt / 2 pi of one ring relative to the other (the stress cycles of both
    rings are proportional to them in pure rolling):
      Q_e = (sum_k Q_e,k^3 Delta n_k / sum_k Delta n_k)^(1/3)   for each ring.
    Before any ball has been loaded during relative rotation the equivalent loads are 0 and the life
    is infinite (``math.inf``).
    """

    #: names of ``state()``'s entries, in order
    STATE_FIELDS = ("sum_cubed_inner", "sum_cubed_outer", "revolutions", "time")

    def __init__(self, ratings: LoadRatings, reliability_factor: float = 1.0):
        if not (math.isfinite(reliability_factor) and 0.0 < reliability_factor <= 1.0):
            raise LifeInputError(f"reliability_factor a1 = {reliability_factor!r} must lie in (0, 1]")
        self.ratings = ratings
        self.reliability_factor = float(reliability_factor)
        self.n_balls = ratings.n_balls
        self.reset()

    def reset(self) -> None:
        """Forget the history."""
        self.sum_cubed_inner = 0.0   # sum_k Q_ei,k^3 Delta n_k [N^3 rev]
        self.sum_cubed_outer = 0.0   # sum_k Q_ee,k^3 Delta n_k [N^3 rev]
        self.revolutions = 0.0       # sum_k Delta n_k, relative revolutions of the rings [rev]
        self.time = 0.0              # accumulated time [s]

    def add(self, loads: Sequence[float], omega_inner: float, omega_outer: float, dt: float,
            load_angular_velocity: float = 0.0) -> None:
        """Add one step of length dt [s] with the ball loads ``loads`` [N] (the first n_balls are used)."""
        if not dt >= 0.0:
            raise LifeInputError(f"time step dt = {dt!r} must be >= 0")
        z = self.n_balls
        s3 = s103 = 0.0
        p_e = P_STATIONARY
        used = loads[:z]
        if len(used) < z:
            raise IndexError(f"{len(used)} ball loads for n_balls = {z}")
        for q in used:
            if q > 0.0:
                s3 += q * q * q
                s103 += q ** p_e
        dn = abs(omega_inner - omega_outer) * dt / _TWO_PI   # revolutions of one ring relative to the other
        if s3 > 0.0:
            q_rot3 = s3 / z                                   # (cubic mean)^3
            q_stat3 = (s103 / z) ** _CUBE_OF_STATIONARY       # ((10/3)-power mean)^3
            if abs(omega_inner - load_angular_velocity) >= abs(omega_outer - load_angular_velocity):
                self.sum_cubed_inner += q_rot3 * dn
                self.sum_cubed_outer += q_stat3 * dn
            else:
                self.sum_cubed_inner += q_stat3 * dn
                self.sum_cubed_outer += q_rot3 * dn
        self.revolutions += dn
        self.time += dt

    # --- results ----------------------------------------------------------------------------------
    @property
    def equivalent_load_inner(self) -> float:
        """Q_ei [N], revolution-weighted cubic mean of the per-step inner-ring equivalent loads."""
        return (self.sum_cubed_inner / self.revolutions) ** (1.0 / 3.0) if self.revolutions > 0 else 0.0

    @property
    def equivalent_load_outer(self) -> float:
        """Q_ee [N], revolution-weighted cubic mean of the per-step outer-ring equivalent loads."""
        return (self.sum_cubed_outer / self.revolutions) ** (1.0 / 3.0) if self.revolutions > 0 else 0.0

    @property
    def life_revolutions(self) -> float:
        """L10r [millions of revolutions of one ring relative to the other]; inf before any load."""
        r = self.ratings
        return rating_life(r.Q_ci, r.Q_ce, self.equivalent_load_inner, self.equivalent_load_outer,
                           self.reliability_factor)

    @property
    def speed(self) -> float:
        """Mean relative speed of the rings over the history [rev/s] (0 before any rotation)."""
        return self.revolutions / self.time if self.time > 0 else 0.0

    @property
    def life_hours(self) -> float:
        """L10r [h] at the history's mean relative speed; inf before any load."""
        life = self.life_revolutions
        return math.inf if math.isinf(life) else life * 1e6 / (self.speed * HOUR)

    # --- state (FMU get/set state) ----------------------------------------------------------------
    def state(self) -> list[float]:
        """The accumulated sums, in STATE_FIELDS order."""
        return [self.sum_cubed_inner, self.sum_cubed_outer, self.revolutions, self.time]

    def restore(self, state: Sequence[float]) -> None:
        """Restore ``state()``; validates all of it before assigning any of it."""
        values = list(state)
        if len(values) != len(self.STATE_FIELDS) or not all(
                isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in values):
            raise LifeInputError(f"not a life accumulator state: {state!r}")
        (self.sum_cubed_inner, self.sum_cubed_outer, self.revolutions, self.time) = (float(v) for v in values)
