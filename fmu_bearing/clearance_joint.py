"""Journal-in-bushing revolute clearance joint with Lankarani-Nikravesh contact (SI units).

The comparison model of Xu et al. (2012), Section 5, Fig. 23(b)-25: "the clearance joint widely
used in the literatures" (their refs. [21-24, 38]: Ravn; Flores et al.), a journal of radius R_j
moving freely inside a bushing of radius R_i = R_j + c until the surfaces touch, then pushed back
by a continuous contact force with hysteresis damping.  It is the drop-in counterpart of
``ball_bearing.BallBearing``: same conventions, same inputs, a result with the same field names.

Conventions (EQUATIONS.md, as in ``ball_bearing``): e = r_journal - r_housing [m], v = de/dt
[m/s]; (F_x, F_y) is the force on the housing (bushing) body, the journal receives -F.  A journal
pushed in +x into the bushing wall gives F_x > 0.

Force law (Lankarani and Nikravesh 1990; as used by Flores et al. 2008 for clearance joints)::

    n = e/|e|,  delta = |e| - c,  delta_dot = v . n
    F_n = K delta^1.5 [1 + 3 (1 - c_r^2)/4 * delta_dot / delta_dot_minus]   for delta > 0, else 0
    F   = max(F_n, 0) n                                                    (a contact cannot pull)

delta_dot_minus is the normal approach speed when the current contact began: STATE, kept
explicitly in ``ContactState`` and advanced by ``ClearanceJoint.update_state`` (the FMU saves and
restores it with the FMU state; the monolithic reference carries it alongside its ODE state).

Impact-velocity guard (the division by delta_dot_minus)
--------------------------------------------------------
The hysteresis factor 3(1 - c_r^2)/(4 delta_dot_minus) is what makes an impact at delta_dot_minus
come back with restitution c_r.  A contact that begins at (almost) zero approach speed - a
grazing re-entry, or a journal that starts in touch - would get an unbounded damping factor.  We
use ``delta_dot_eff = max(delta_dot_minus, min_impact_velocity)``:

* impacts faster than ``min_impact_velocity`` follow Lankarani-Nikravesh exactly (restitution c_r);
* slower contacts get the constant hysteresis factor chi_max = 3(1 - c_r^2)/(4 v_min) [s/m]: the
  law becomes a Hunt-Crossley-type law F_n = K delta^1.5 (1 + chi_max delta_dot) (Hunt and Crossley
  1975), whose restitution rises towards 1 as the impact slows, c_r(v) ~ sqrt(1 - (1 - c_r^2) v/v_min),
  which is also what experiments show for metals (1 - c_r roughly proportional to v; Goldsmith 1960).

The alternative, a stateless Hunt-Crossley-type law with a fixed factor everywhere, is what this
law becomes for ``min_impact_velocity`` above every impact speed; it needs no state (simpler FMU
rollback) but does not reproduce c_r = 0.9 at the impact speeds of refs. [21-24, 38], so it is
not the model the paper compares against.  The default v_min = 1e-2 m/s (not smaller) because the
guard sets the damping of the paper's regime, continuous contact under a slowly varying load:
linearised about a mean load F_0 with deflection delta_0 = (F_0/K)^(2/3) and effective mass m,
the damping ratio is zeta = (chi/2) sqrt(F_0 delta_0 / (1.5 m)) with chi = 3(1 - c_r^2)/(4 v_eff).
For the defaults (K = 5.76e11 N/m^1.5), F_0 = 300 N, m = 0.3 kg that is zeta = 0.15 at v_min = 1e-2,
1.5 at 1e-3 and 15 at 1e-4 m/s (at F_0 = 30 N: 0.02, 0.2, 2.2).  A guard of 1e-4 m/s would bury the
elastic vibrations that the paper still sees in Fig. 25 (its "different elastic vibration
frequency"), add a damping rate c/m ~ 1e6 1/s (a stiff term for an explicit co-simulation step),
and clamp the force to zero whenever the contact unloads faster than 4 v_eff / (3 (1 - c_r^2)),
about 7 v_eff (0.7 mm/s with a 1e-4 m/s guard).  Real impacts in that mechanism (the journal crossing c to 2c = 10-20 um
under 1e2-1e3 m/s^2) come in at about 0.05-0.2 m/s, above the guard, which leaves them untouched.
See also ``hysteresis_factor``.

Stiffness: sphere-to-sphere internal contact, as the paper says refs. [21-23, 38] use
(``sphere_contact_stiffness``).  It is much stiffer than one ball of the bearing (about 60x for the
defaults), hence the different elastic vibration frequency the paper reports in Fig. 25.

References
----------
* H.M. Lankarani, P.E. Nikravesh, A contact force model with hysteresis damping for impact
  analysis of multibody systems, J. Mech. Des. 112 (1990) 369-376.
* P. Flores, J. Ambrosio, J.C.P. Claro, H.M. Lankarani, Kinematics and Dynamics of Multibody
  Systems with Imperfect Joints, Lecture Notes in Applied and Computational Mechanics 34,
  Springer, 2008, and P. Flores' PhD thesis, Universidade do Minho, 2005: "Flores' literature [38]"
  of the paper, for the clearance-joint formulation and the contact stiffness (the extraction's
  reference list is cut off after [3], so the exact entries [21-24, 38] could not be checked).
* P. Ravn, A continuous analysis method for planar multibody systems with joint clearance,
  Multibody Syst. Dyn. 2 (1998) 1-24.
* K.H. Hunt, F.R.E. Crossley, Coefficient of restitution interpreted as damping in vibroimpact,
  J. Appl. Mech. 42 (1975) 440-445.
* W. Goldsmith, Impact, Edward Arnold, London, 1960.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import NamedTuple

from .ball_bearing import BearingInputError, check_joint_inputs  # noqa: F401 (re-exported: its error type)
from .parameters import BearingParameterError, BearingParameters, _param

#: The ball bearing's diametral clearance P_d [m]; this joint's default per-side clearance is P_d / 2.
_BEARING_DIAMETRAL_CLEARANCE = BearingParameters().radial_clearance

#: Default eccentricity limit as a fraction of the journal radius (used when eccentricity_limit = 0).
ECCENTRICITY_LIMIT_FRACTION = 0.05


@dataclass(frozen=True)
class ClearanceParameters:
    """Geometry, material and contact law of a journal in a bushing with clearance (SI units).

    ``radial_clearance`` c is the bushing radius minus the journal radius, R_i - R_j: the free
    radial travel per side before the surfaces touch.  Its default equals the ball bearing's per-side
    clearance P_d/2 = 1.0e-5 m (Table 2: P_d = 0.02 mm), so both joints have the same free play.
    The journal radius defaults to the bearing's bore radius (24 mm / 2); journal and bushing
    are both steel (Table 2's E and nu).
    """

    radial_clearance: float = _param(0.5 * _BEARING_DIAMETRAL_CLEARANCE, "m",
                                     "radial clearance c = bushing radius - journal radius (free play per side; "
                                     "default P_d/2 of the ball bearing)")
    journal_radius: float = _param(0.012, "m", "journal radius R_j (the bushing radius is R_j + c)")
    restitution: float = _param(0.9, "1", "coefficient of restitution c_r of the hysteresis damping, in (0, 1]")
    youngs_modulus: float = _param(207e9, "Pa", "Young's modulus E of journal and bushing")
    poisson_ratio: float = _param(0.3, "1", "Poisson's ratio nu of journal and bushing, in (0, 0.5)")
    contact_stiffness: float = _param(0.0, "N/m1.5", "contact stiffness K override; 0 = sphere-to-sphere "
                                                     "Hertz from geometry")
    min_impact_velocity: float = _param(1.0e-2, "m/s", "lower bound v_min on the recorded impact velocity in the "
                                                       "damping term (guard against contacts that begin at rest)")
    eccentricity_limit: float = _param(0.0, "m", "|e| beyond this is divergence (error); 0 = 5 % of journal_radius")

    def replace(self, **changes) -> "ClearanceParameters":
        return replace(self, **changes)

    def as_dict(self) -> dict:
        return asdict(self)

    @property
    def bushing_radius(self) -> float:
        """R_i = R_j + c [m]."""
        return self.journal_radius + self.radial_clearance

    @property
    def effective_eccentricity_limit(self) -> float:
        """|e| limit [m]: ``eccentricity_limit`` or, if 0, 5 % of the journal radius (0.6 mm by default)."""
        return (self.eccentricity_limit if self.eccentricity_limit > 0
                else ECCENTRICITY_LIMIT_FRACTION * self.journal_radius)

    def validate(self) -> None:
        """Raise BearingParameterError naming the first invalid parameter."""
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise BearingParameterError(f.name, v, "must be a finite number")
        if self.journal_radius <= 0:
            raise BearingParameterError("journal_radius", self.journal_radius, "must be positive")
        if self.radial_clearance < 0:
            raise BearingParameterError("radial_clearance", self.radial_clearance, "must not be negative")
        if self.radial_clearance == 0 and self.contact_stiffness == 0:
            raise BearingParameterError(
                "radial_clearance", self.radial_clearance,
                "must be positive for the sphere-to-sphere stiffness (K grows like c^-1/2); "
                "set contact_stiffness to use a zero clearance")
        if not 0.0 < self.restitution <= 1.0:
            raise BearingParameterError("restitution", self.restitution, "must lie in (0, 1]")
        if self.youngs_modulus <= 0:
            raise BearingParameterError("youngs_modulus", self.youngs_modulus, "must be positive")
        if not 0.0 < self.poisson_ratio < 0.5:
            raise BearingParameterError("poisson_ratio", self.poisson_ratio, "must lie in (0, 0.5)")
        if self.contact_stiffness < 0:
            raise BearingParameterError("contact_stiffness", self.contact_stiffness, "must not be negative")
        if self.min_impact_velocity <= 0:
            raise BearingParameterError("min_impact_velocity", self.min_impact_velocity,
                                        "must be positive (it bounds the hysteresis damping factor)")
        if self.eccentricity_limit < 0:
            raise BearingParameterError("eccentricity_limit", self.eccentricity_limit, "must not be negative")
        if self.effective_eccentricity_limit <= self.radial_clearance:
            raise BearingParameterError("eccentricity_limit", self.eccentricity_limit,
                                        f"must exceed radial_clearance = {self.radial_clearance!r}")


CLEARANCE_PARAMETER_NAMES = tuple(f.name for f in fields(ClearanceParameters))


def compliance(youngs_modulus: float, poisson_ratio: float) -> float:
    """sigma = (1 - nu^2) / E [1/Pa], the material compliance of Lankarani and Nikravesh (1990) and Flores et al. (2008)."""
    return (1.0 - poisson_ratio * poisson_ratio) / youngs_modulus


def sphere_contact_stiffness(bushing_radius: float, journal_radius: float,
                             youngs_modulus_bushing: float, poisson_ratio_bushing: float,
                             youngs_modulus_journal: float | None = None,
                             poisson_ratio_journal: float | None = None) -> float:
    """Hertz load-deflection constant of a sphere inside a spherical cavity [N/m^1.5].

    K = (4/3) / (sigma_i + sigma_j) * sqrt(R_i R_j / (R_i - R_j)),  sigma_k = (1 - nu_k^2) / E_k,

    with R_i the bushing (concave) and R_j the journal radius, R_i > R_j.  This is Hertz's
    F = (4/3) E* sqrt(R) delta^1.5 for two spheres, 1/E* = sigma_i + sigma_j and
    1/R = 1/R_j - 1/R_i (the concave radius counts negative): the sphere-to-sphere stiffness that
    Lankarani and Nikravesh (1990) and Flores et al. (2008; Flores' thesis 2005)
    use for revolute clearance joints, as Xu et al. (2012, end of Sec. 5) state (strictly a cylinder in
    a cylinder, but those references use the sphere formula).  Journal material defaults to the
    bushing's.
    """
    E_j = youngs_modulus_bushing if youngs_modulus_journal is None else youngs_modulus_journal
    nu_j = poisson_ratio_bushing if poisson_ratio_journal is None else poisson_ratio_journal
    if not bushing_radius > journal_radius > 0:
        raise ValueError(f"need bushing_radius > journal_radius > 0, got {bushing_radius!r}, {journal_radius!r}")
    sigma = compliance(youngs_modulus_bushing, poisson_ratio_bushing) + compliance(E_j, nu_j)
    effective_radius = bushing_radius * journal_radius / (bushing_radius - journal_radius)
    return (4.0 / 3.0) / sigma * math.sqrt(effective_radius)


def hysteresis_factor(restitution: float) -> float:
    """3 (1 - c_r^2) / 4 [-], Lankarani and Nikravesh (1990): the damping factor times delta_dot_minus."""
    return 0.75 * (1.0 - restitution * restitution)


class ContactState(NamedTuple):
    """The law's state between steps: whether a contact is under way and how it began.

    impact_velocity: the normal approach speed delta_dot_minus [m/s] recorded when delta crossed 0
    (0.0 when not in contact; never negative).
    """

    in_contact: bool = False
    impact_velocity: float = 0.0


class ClearanceForce(NamedTuple):
    """Result of one evaluation (SI), field for field like ``ball_bearing.BearingForce`` up to c_yy.

    The stiffness dF/de is not symmetric when the hysteresis damping acts: the normal n = e/|e|
    turns with the tangential velocity, which adds (K delta^1.5 chi/|e|) n v_t^T.  k_xy is the
    symmetric part (dF_x/de_y + dF_y/de_x)/2, so a caller that treats the matrix as symmetric, as
    the master does for the ball bearing, uses the nearest symmetric matrix; the exact Jacobian is
    [[k_xx, k_xy + k_skew], [k_xy - k_skew, k_yy]].  dF/dv = c_n n n^T is symmetric.
    """

    F_x: float              # [N]
    F_y: float              # [N]
    k_xx: float             # dF_x/de_x [N/m]
    k_xy: float             # (dF_x/de_y + dF_y/de_x)/2 [N/m]
    k_yy: float             # dF_y/de_y [N/m]
    c_xx: float             # dF_x/dv_x [N s/m]
    c_xy: float             # dF_x/dv_y = dF_y/dv_x [N s/m]
    c_yy: float             # dF_y/dv_y [N s/m]
    k_skew: float           # (dF_x/de_y - dF_y/de_x)/2 [N/m]
    penetration: float      # delta = |e| - c [m], negative inside the clearance
    contact_force: float    # F_n >= 0 [N]
    normal_velocity: float  # delta_dot = v . n [m/s] (0 at e = 0)


class ClearanceJoint:
    """A validated journal-bushing clearance joint with its constants precomputed.

    Stateless itself: the contact state travels in ``ContactState`` values, advanced by
    ``update_state``, so that FMUs, the co-simulation master and the monolithic reference own it.
    """

    def __init__(self, params: ClearanceParameters | None = None):
        p = params if params is not None else ClearanceParameters()
        p.validate()
        self.params = p
        if p.contact_stiffness > 0:
            self.stiffness = float(p.contact_stiffness)
        else:
            self.stiffness = sphere_contact_stiffness(p.bushing_radius, p.journal_radius,
                                                      p.youngs_modulus, p.poisson_ratio)
        self.clearance = float(p.radial_clearance)
        self.eccentricity_limit = float(p.effective_eccentricity_limit)
        self.min_impact_velocity = float(p.min_impact_velocity)
        self.hysteresis = hysteresis_factor(p.restitution)

    # --- inputs and state -------------------------------------------------------------------------
    def check_inputs(self, e_x: float, e_y: float, v_x: float, v_y: float,
                     omega_inner: float = 0.0, omega_outer: float = 0.0) -> None:
        """Raise BearingInputError on non-finite inputs or |e| beyond the divergence limit.

        The ring speeds are unused by this law; they are checked so both joints reject the same inputs.
        """
        check_joint_inputs(self.eccentricity_limit, e_x, e_y, v_x, v_y, omega_inner, omega_outer)

    def penetration(self, e_x: float, e_y: float) -> float:
        """delta = |e| - c [m]; positive in contact."""
        return math.hypot(e_x, e_y) - self.clearance

    @staticmethod
    def normal_velocity(e_x: float, e_y: float, v_x: float, v_y: float) -> float:
        """delta_dot = v . e/|e| [m/s] (0 at e = 0)."""
        e = math.hypot(e_x, e_y)
        return (v_x * e_x + v_y * e_y) / e if e > 0.0 else 0.0

    def update_state(self, state: ContactState, e_x: float, e_y: float, v_x: float, v_y: float) -> ContactState:
        """The contact state at (e, v), given the state before: call it at the end of each step.

        delta <= 0: no contact.  delta > 0 and already in contact: unchanged.  delta > 0 after no
        contact: the contact begins now, delta_dot_minus = max(v . n, 0) (a contact first seen while
        already receding records 0 and gets the guard).  The entry is sampled at the caller's step:
        with coarse steps the recorded speed is the approach speed at the first sample in contact.
        """
        if self.penetration(e_x, e_y) <= 0.0:
            return ContactState(False, 0.0)
        if state.in_contact:
            return state
        return ContactState(True, max(self.normal_velocity(e_x, e_y, v_x, v_y), 0.0))

    def effective_impact_velocity(self, impact_velocity: float) -> float:
        """delta_dot_minus used in the damping: max(impact_velocity, min_impact_velocity) [m/s]."""
        return max(impact_velocity, self.min_impact_velocity)

    # --- force law ------------------------------------------------------------------------------
    def evaluate(self, e_x: float, e_y: float, v_x: float, v_y: float, impact_velocity: float) -> ClearanceForce:
        """Contact force on the housing and its tangent matrices, for the recorded impact velocity [m/s].

        F_n = K delta^1.5 (1 + chi delta_dot), chi = 3(1 - c_r^2) / (4 max(impact_velocity, v_min)),
        clamped at 0, F = F_n n.  Tangents (where F_n > 0; zero where the force is zero):
        dF/de = (1.5 F_n/delta) n n^T + (F_n/|e|)(I - n n^T) + (K delta^1.5 chi/|e|) n v_t^T,
        dF/dv = K delta^1.5 chi n n^T, with v_t = v - delta_dot n.
        """
        e = math.hypot(e_x, e_y)
        delta = e - self.clearance
        if e <= 0.0:
            return ClearanceForce(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, delta, 0.0, 0.0)
        nx, ny = e_x / e, e_y / e
        vn = v_x * nx + v_y * ny
        if delta <= 0.0:                            # inside the clearance: free flight
            return ClearanceForce(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, delta, 0.0, vn)
        chi = self.hysteresis / self.effective_impact_velocity(impact_velocity)   # [s/m]
        elastic = self.stiffness * delta * math.sqrt(delta)                        # K delta^1.5 [N]
        fn = elastic * (1.0 + chi * vn)
        if fn <= 0.0:                               # a contact cannot pull: clamp at zero
            return ClearanceForce(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, delta, 0.0, vn)
        a = 1.5 * fn / delta                        # dF_n/d delta [N/m]
        g = fn / e                                  # geometric stiffness of the turning normal [N/m]
        cn = elastic * chi                          # dF_n/d delta_dot [N s/m]
        b = cn / e                                  # dF_n/d e through delta_dot = v . n [N s/m / m]
        vtx, vty = v_x - vn * nx, v_y - vn * ny
        nxx, nxy, nyy = nx * nx, nx * ny, ny * ny
        k_xy = (a - g) * nxy + 0.5 * b * (nx * vty + ny * vtx)
        k_skew = 0.5 * b * (nx * vty - ny * vtx)
        return ClearanceForce(
            fn * nx, fn * ny,
            a * nxx + g * (1.0 - nxx) + b * nx * vtx, k_xy, a * nyy + g * (1.0 - nyy) + b * ny * vty,
            cn * nxx, cn * nxy, cn * nyy,
            k_skew, delta, fn, vn)

    def evaluate_with_state(self, state: ContactState, e_x: float, e_y: float, v_x: float, v_y: float
                            ) -> tuple[ClearanceForce, ContactState]:
        """``update_state`` then ``evaluate`` with the updated state: the force at (e, v) after the state before.

        What the FMU does at the end of a step, and what a monolithic right-hand side can call
        with its last accepted state (a contact that begins inside the step then uses its own
        approach speed rather than the guard).
        """
        new = self.update_state(state, e_x, e_y, v_x, v_y)
        return self.evaluate(e_x, e_y, v_x, v_y, new.impact_velocity), new

    def elastic_energy(self, e_x: float, e_y: float) -> float:
        """Strain energy of the elastic part, (2/5) K delta^2.5 [J] (tests, energy balance)."""
        delta = self.penetration(e_x, e_y)
        return 0.4 * self.stiffness * delta * delta * math.sqrt(delta) if delta > 0.0 else 0.0
