"""The deep-groove ball bearing force law of Xu et al. (2012), Section 3-4, in SI units.

One home for the physics: the BallBearing FMU, the co-simulation master's in-process
path, the monolithic reference and the tests all call ``BallBearing.evaluate``.

Conventions (EQUATIONS.md): e = r_journal - r_housing [m], v its time derivative [m/s];
(F_x, F_y) is the force on the housing body (eq. 19-20), the journal receives -F (eq. 22).
A journal pushed in +x compresses ball 1 at phi = 0 and F_x > 0.

Departures from the paper (docs/modelling-choices.md):
* the cage angle is the time integral of omega_m (eq. 16), not omega_m * t (eq. 17);
* a loaded ball whose damping term would make the force negative carries 0 N (a contact
  cannot pull); inside the clearance the force is 0, damping included (eq. 18);
* besides F, ``evaluate`` returns the tangent stiffness dF/de and damping dF/dv matrices
  (the bearing's linearised stiffness), which the master's default coupling scheme uses.
"""
from __future__ import annotations

import math
from typing import NamedTuple, MutableSequence

from . import hertz
from .parameters import (DAMPING_CONSTANT, DAMPING_OIL_FILM, BearingParameters, validate)

#: The squeeze-film literature writes c = 3 pi eta a^4 / (2 h^3); the paper's extraction shows no pi.
#: We keep pi (the Reynolds squeeze film of a disc); set to 1.0 for the paper as printed.
OIL_FILM_PI = math.pi
#: Exponents of eq. (31), h0 = 1.15 R (u eta alpha / R)^0.744 (E R^2 / W)^0.078 (best reading of the extraction).
FILM_SPEED_EXPONENT, FILM_LOAD_EXPONENT, FILM_COEFFICIENT = 0.744, 0.078, 1.15


_cos, _sin, _sqrt = math.cos, math.sin, math.sqrt
#: BearingForce(*values) without the Python-level __new__ of a NamedTuple: the same object, faster
_new_tuple = tuple.__new__


class BearingInputError(ValueError):
    """Inputs the force law cannot accept (NaN/inf, or an eccentricity beyond the divergence limit)."""


class BearingForce(NamedTuple):
    """Result of one force-law evaluation (SI): force on the housing and its tangent matrices."""

    F_x: float            # [N]
    F_y: float            # [N]
    k_xx: float           # dF_x/de_x [N/m]
    k_xy: float           # dF_x/de_y = dF_y/de_x [N/m]
    k_yy: float           # dF_y/de_y [N/m]
    c_xx: float           # dF_x/dv_x [N s/m]
    c_xy: float           # dF_x/dv_y = dF_y/dv_x [N s/m]
    c_yy: float           # dF_y/dv_y [N s/m]
    loaded_balls: int     # balls carrying load [-]
    max_ball_load: float  # [N]


def check_joint_inputs(eccentricity_limit: float, e_x: float, e_y: float, v_x: float, v_y: float,
                       omega_inner: float = 0.0, omega_outer: float = 0.0) -> None:
    """The input check every joint component shares: finite inputs, |e| within the divergence limit [m]."""
    # Fast path (per doStep): a finite sum implies six finite inputs (an inf gives inf, a NaN or inf - inf NaN);
    # a non-finite sum (also an overflow of finite ones) goes through the loop, which names the culprit.
    if not math.isfinite(e_x + e_y + v_x + v_y + omega_inner + omega_outer):
        _check_finite(e_x, e_y, v_x, v_y, omega_inner, omega_outer)
    e = math.hypot(e_x, e_y)
    if e > eccentricity_limit:
        raise BearingInputError(
            f"eccentricity |e| = {e:.6g} m exceeds eccentricity_limit = {eccentricity_limit:.6g} m "
            f"(the calling simulation has diverged)")


def _check_finite(e_x, e_y, v_x, v_y, omega_inner, omega_outer) -> None:
    """Raise BearingInputError naming the first non-finite input."""
    for name, value in (("e_x", e_x), ("e_y", e_y), ("v_x", v_x), ("v_y", v_y),
                        ("omega_inner", omega_inner), ("omega_outer", omega_outer)):
        if not math.isfinite(value):
            raise BearingInputError(f"input {name} = {value!r} is not a finite number")


def cage_angular_velocity(omega_inner: float, omega_outer: float, d_inner: float, d_outer: float) -> float:
    """omega_m = (omega_i d_i + omega_o d_o) / (d_i + d_o), eq. (16) (no gross slip)."""
    return (omega_inner * d_inner + omega_outer * d_outer) / (d_inner + d_outer)


class BallBearing:
    """A validated bearing with everything precomputed that does not change per call."""

    def __init__(self, params: BearingParameters | None = None, capacity: int | None = None):
        p = params if params is not None else BearingParameters()
        validate(p, capacity)
        self.params = p
        self.n_balls = int(p.n_balls)
        if p.contact_stiffness > 0:
            self.stiffness = float(p.contact_stiffness)
        else:  # eq. (24)-(28), exact Hertz
            self.stiffness = float(hertz.ball_stiffness(p.ball_diameter, p.pitch_diameter, p.youngs_modulus,
                                                        p.poisson_ratio, p.inner_groove_conformity,
                                                        p.outer_groove_conformity))
        self.half_clearance = 0.5 * p.radial_clearance
        self.eccentricity_limit = p.effective_eccentricity_limit
        self.damping_model = int(p.damping_model)
        self.damping_coefficient = float(p.damping_coefficient)
        # Ball directions in the cage frame (ball r at 2 pi (r-1)/N_b, eq. 17) and their outer products.
        self._balls = tuple(
            (r, math.cos(a), math.sin(a), math.cos(a) ** 2, math.cos(a) * math.sin(a), math.sin(a) ** 2)
            for r, a in ((r, 2.0 * math.pi * r / self.n_balls) for r in range(self.n_balls)))
        d_i, d_o = p.inner_race_diameter, p.outer_race_diameter
        self._w_inner, self._w_outer = d_i / (d_i + d_o), d_o / (d_i + d_o)
        # Pure-rolling entrainment speed u = |omega_i - omega_o| d_i d_o / (2 (d_i + d_o)), same at both contacts.
        self._entrainment = d_i * d_o / (2.0 * (d_i + d_o))
        self._oil = self._oil_film_constants(p) if self.damping_model == DAMPING_OIL_FILM else None
        self._unused_loads = [0.0] * self.n_balls   # evaluate() writes here when it is given no ``loads``

    # --- kinematics -----------------------------------------------------------------------------
    def cage_velocity(self, omega_inner: float, omega_outer: float) -> float:
        """Angular velocity of the cage and ball set [rad/s], eq. (16)."""
        return omega_inner * self._w_inner + omega_outer * self._w_outer

    def advance_cage(self, cage_angle: float, omega_inner: float, omega_outer: float, dt: float) -> float:
        """Cage angle after dt [s] with the ring speeds held: the time integral of eq. (16)."""
        return cage_angle + dt * (omega_inner * self._w_inner + omega_outer * self._w_outer)

    def ball_angles(self, cage_angle: float) -> list[float]:
        """phi_r = cage_angle + 2 pi (r-1)/N_b [rad], eq. (17) with the integrated cage angle."""
        return [cage_angle + 2.0 * math.pi * r / self.n_balls for r in range(self.n_balls)]

    def deflection(self, e_x: float, e_y: float, phi: float) -> float:
        """delta_r = e . u_r - P_d/2 [m] of the ball at angle ``phi`` [rad] (eq. 18's bracket, u_r = (cos phi,
        sin phi)): > 0 in the load zone. (``evaluate`` forms the same in the cage frame.)"""
        return e_x * math.cos(phi) + e_y * math.sin(phi) - self.half_clearance

    @staticmethod
    def deflection_rate(e_x: float, e_y: float, v_x: float, v_y: float, phi: float, omega: float) -> float:
        """d delta_r / dt [m/s] of the ball at angle ``phi`` [rad] carried round at the cage speed ``omega`` [rad/s]
        (eq. 16-17): v . u_r + omega e . u_r', with u_r' = d u_r / d phi = (-sin phi, cos phi)."""
        c, s = math.cos(phi), math.sin(phi)
        return v_x * c + v_y * s + omega * (e_y * c - e_x * s)

    def check_inputs(self, e_x: float, e_y: float, v_x: float, v_y: float,
                     omega_inner: float = 0.0, omega_outer: float = 0.0) -> None:
        """Raise BearingInputError on non-finite inputs or |e| beyond the divergence limit."""
        check_joint_inputs(self.eccentricity_limit, e_x, e_y, v_x, v_y, omega_inner, omega_outer)

    # --- force law ------------------------------------------------------------------------------
    def evaluate(self, e_x: float, e_y: float, v_x: float, v_y: float, cage_angle: float,
                 omega_inner: float = 0.0, omega_outer: float = 0.0,
                 loads: MutableSequence[float] | None = None) -> BearingForce:
        """Per-ball loads (eq. 18) and the resultant (eq. 19) with its tangent stiffness and damping.

        F_r = [K delta_r^1.5 + C (v . u_r)]_+ for delta_r = e . u_r - P_d/2 > 0, else 0, where
        u_r = (cos phi_r, sin phi_r). ``loads``, if given, receives the N_b ball loads [N].
        The ring speeds matter only for the oil-film damping (entrainment speed).
        """
        # (speed: called once per co-simulation step; every expression keeps its order of operations, so
        # the results are the same doubles as the plain form: 1.5 * K * root is (1.5 * K) * root)
        c, s = _cos(cage_angle), _sin(cage_angle)
        # e and v in the cage frame, where ball r sits at the fixed angle 2 pi r / N_b.
        ex, ey = c * e_x + s * e_y, c * e_y - s * e_x
        vx, vy = c * v_x + s * v_y, c * v_y - s * v_x
        K, half = self.stiffness, self.half_clearance
        K15 = 1.5 * K
        C = self.damping_coefficient if self.damping_model == DAMPING_CONSTANT else 0.0
        oil = self._oil
        speed = (self._entrainment * abs(omega_inner - omega_outer)) ** FILM_SPEED_EXPONENT if oil else 0.0
        if loads is None:
            loads = self._unused_loads
        fx = fy = kxx = kxy = kyy = cc = cs_ = ss = 0.0
        n_loaded, f_max = 0, 0.0
        for r, cr, sr, crr, crs, srr in self._balls:
            delta = ex * cr + ey * sr - half
            if delta <= 0.0:                       # outside the load zone: no force, damping included
                loads[r] = 0.0
                continue
            root = _sqrt(delta)
            w = K * delta * root                   # Hertz, eq. (18)
            vr = vx * cr + vy * sr
            if oil is not None:                    # eq. (29)-(32)
                C, dC_dW = self._oil_film_damping(w, speed)
                kt = K15 * root * (1.0 + dC_dW * vr)
            else:
                kt = K15 * root
            f = w + C * vr
            if f <= 0.0:                           # a contact cannot pull: clamp at zero
                loads[r] = 0.0
                continue
            loads[r] = f
            fx += f * cr
            fy += f * sr
            kxx += kt * crr
            kxy += kt * crs
            kyy += kt * srr
            cc += C * crr
            cs_ += C * crs
            ss += C * srr
            n_loaded += 1
            if f > f_max:
                f_max = f
        # Back to the global frame: F = R f, K = R k R^T (eq. 19).
        c2, s2, cs2 = c * c, s * s, c * s
        return _new_tuple(BearingForce, (
            c * fx - s * fy, s * fx + c * fy,
            c2 * kxx - 2.0 * cs2 * kxy + s2 * kyy, cs2 * (kxx - kyy) + (c2 - s2) * kxy,
            s2 * kxx + 2.0 * cs2 * kxy + c2 * kyy,
            c2 * cc - 2.0 * cs2 * cs_ + s2 * ss, cs2 * (cc - ss) + (c2 - s2) * cs_,
            s2 * cc + 2.0 * cs2 * cs_ + c2 * ss,
            n_loaded, f_max))

    def elastic_energy(self, e_x: float, e_y: float, cage_angle: float) -> float:
        """Strain energy stored in the loaded contacts, sum of (2/5) K delta_r^2.5 [J] (tests, energy balance)."""
        total = 0.0
        for phi in self.ball_angles(cage_angle):
            delta = self.deflection(e_x, e_y, phi)
            if delta > 0:
                total += 0.4 * self.stiffness * delta ** 2.5
        return total

    # --- oil-film damping (eq. 29-32) ---------------------------------------------------------
    @staticmethod
    def _oil_film_constants(p: BearingParameters) -> tuple:
        ci, co = hertz.raceway_contacts(p.ball_diameter, p.pitch_diameter,
                                        p.inner_groove_conformity, p.outer_groove_conformity)
        E, nu, eta, alpha = p.youngs_modulus, p.poisson_ratio, p.oil_viscosity, p.pressure_viscosity_coefficient
        consts = []
        for R in (ci.R_x, co.R_x):
            # eq. (30): a = 1.109 (W R / E)^(1/3) is (3 W R / (4 E*))^(1/3), E* = E / (2 (1 - nu^2)), for nu = 0.3.
            a4 = (1.5 * (1.0 - nu * nu) * R / E) ** (4.0 / 3.0)          # a^4 = a4 * W^(4/3)
            # eq. (31): h0 = 1.15 R (u eta alpha / R)^0.744 (E R^2 / W)^0.078 = h * u^0.744 * W^-0.078
            h = FILM_COEFFICIENT * R * (eta * alpha / R) ** FILM_SPEED_EXPONENT * (E * R * R) ** FILM_LOAD_EXPONENT
            consts.append((float(1.5 * OIL_FILM_PI * eta * a4), float(h)))              # eq. (29): c = 3 pi eta a^4 / (2 h0^3)
        return tuple(consts), p.min_film_thickness

    def _oil_film_damping(self, load: float, speed_factor: float) -> tuple[float, float]:
        """Ball damping C [N s/m] of the inner and outer films in series (eq. 32) and dC/dW [s/m]."""
        (contacts, h_min) = self._oil
        w43 = load ** (4.0 / 3.0)
        wl = load ** -FILM_LOAD_EXPONENT
        cs, dcs = [], []
        for pre, h in contacts:
            h0 = h * speed_factor * wl
            if h0 > h_min:
                c = pre * w43 / (h0 * h0 * h0)
                dc = c * (4.0 / 3.0 + 3.0 * FILM_LOAD_EXPONENT) / load
            else:                                  # film at the roughness floor: h0 = min_film_thickness
                c = pre * w43 / (h_min ** 3)
                dc = c * (4.0 / 3.0) / load
            cs.append(c)
            dcs.append(dc)
        (ci, co), (dci, dco) = cs, dcs
        total = ci + co
        return ci * co / total, (co * co * dci + ci * ci * dco) / (total * total)

    def oil_film_damping(self, load: float, omega_inner: float, omega_outer: float) -> float:
        """Ball damping coefficient C [N s/m] of the oil-film model at a ball load [N] (eq. 29-32)."""
        if self._oil is None:
            raise ValueError("damping_model is not the oil-film model (2)")
        speed = (self._entrainment * abs(omega_inner - omega_outer)) ** FILM_SPEED_EXPONENT
        return self._oil_film_damping(load, speed)[0]
