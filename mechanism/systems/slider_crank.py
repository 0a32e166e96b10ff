"""The slider-crank mechanism of Xu et al. 2012, Section 5 (Table 1), as model data.

Bodies (in coordinate order): "crank", "rod" (connecting rod), "slider".
Joints: ground-crank revolute, constant-speed crank driver, crank-rod connection
(ideal revolute, or the ball bearing as a force joint), rod-slider revolute,
slider-ground translational joint along the global x axis.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mechanism.multibody.model import (
    GROUND,
    AngleDriver,
    BearingJoint,
    Body,
    Model,
    Point,
    Revolute,
    Translational,
)
from mechanism.multibody.solver import System

STANDARD_GRAVITY = 9.81
"""Gravitational acceleration [m/s^2] used when ``SliderCrankParameters.gravity`` is set."""

CRANK, ROD, SLIDER = "crank", "rod", "slider"
JOINT_TYPES = ("bearing", "ideal")


@dataclass(frozen=True)
class SliderCrankParameters:
    """Table 1 of the paper, SI units.

    Centres of mass at mid-length (not stated in the paper; the classic benchmark these
    numbers come from assumes it). slider_inertia is not given in the paper: the slider
    cannot rotate, so its value does not affect the motion; 1.0e-4 kg m^2 is used.
    housing_radius = outer diameter 52 mm / 2, journal_radius = bore 24 mm / 2 (Table 2).
    gravity: if True, -9.81 m/s^2 along -y; the paper's example has none.
    """

    crank_length: float = 0.050          # m
    crank_mass: float = 0.30             # kg
    crank_inertia: float = 1.0e-4        # kg m^2 (100 kg mm^2)
    rod_length: float = 0.120            # m
    rod_mass: float = 0.21               # kg
    rod_inertia: float = 2.5e-4          # kg m^2 (250 kg mm^2)
    slider_mass: float = 0.14            # kg
    slider_inertia: float = 1.0e-4       # kg m^2 (not in the paper; irrelevant, cannot rotate)
    rpm: float = 1200.0                  # crank speed, rev/min
    gravity: bool = False
    housing_radius: float = 0.026        # m
    journal_radius: float = 0.012        # m

    @property
    def omega(self) -> float:
        """Crank angular velocity [rad/s]."""
        return self.rpm * 2.0 * math.pi / 60.0


def crank_pin_points(params: SliderCrankParameters) -> tuple[Point, Point]:
    """(point on the crank, point on the rod) of the crank-rod connection."""
    return (Point(CRANK, (0.5 * params.crank_length, 0.0)),
            Point(ROD, (-0.5 * params.rod_length, 0.0)))


def build(params: SliderCrankParameters = SliderCrankParameters(), joint: str = "bearing") -> Model:
    """The slider-crank as a Model; ``joint`` = "bearing" (force joint) or "ideal" (revolute)."""
    if joint not in JOINT_TYPES:
        raise ValueError(f"joint must be one of {JOINT_TYPES}, not {joint!r}")
    L1, L2 = params.crank_length, params.rod_length
    bodies = (Body(CRANK, params.crank_mass, params.crank_inertia),
              Body(ROD, params.rod_mass, params.rod_inertia),
              Body(SLIDER, params.slider_mass, params.slider_inertia))
    on_crank, on_rod = crank_pin_points(params)
    joints = [Revolute("ground_crank", Point(GROUND, (0.0, 0.0)), Point(CRANK, (-0.5 * L1, 0.0))),
              AngleDriver("crank_driver", CRANK, omega=params.omega, theta0=0.0)]
    bearings: tuple[BearingJoint, ...] = ()
    if joint == "ideal":
        joints.append(Revolute("crank_rod", on_crank, on_rod))
    else:   # outer ring (housing) on the crank, inner ring (journal) on the rod
        bearings = (BearingJoint("bearing", on_crank, on_rod,
                                 params.housing_radius, params.journal_radius),)
    joints += [Revolute("rod_slider", Point(ROD, (0.5 * L2, 0.0)), Point(SLIDER, (0.0, 0.0))),
               Translational("slider_ground", Point(GROUND, (0.0, 0.0)), Point(SLIDER, (0.0, 0.0)),
                             axis=(1.0, 0.0), angle0=0.0)]
    gravity = (0.0, -STANDARD_GRAVITY) if params.gravity else (0.0, 0.0)
    return Model(bodies=bodies, joints=tuple(joints), bearings=bearings, gravity=gravity)


def initial_state(system: System, params: SliderCrankParameters = SliderCrankParameters()
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The paper's start (Fig. 10): crank angle 0, crank and rod collinear along +x,
    slider at x = L1 + L2, housing and journal centres coincident, and the velocities of
    the ideal mechanism (valid for both joint types: the coordinates are the same)."""
    L1, L2 = params.crank_length, params.rod_length
    ideal = System(build(params, "ideal"), system.alpha, system.beta)
    q0 = np.zeros(ideal.n)
    q0[ideal.slice(CRANK)] = (0.5 * L1, 0.0, 0.0)
    q0[ideal.slice(ROD)] = (L1 + 0.5 * L2, 0.0, 0.0)
    q0[ideal.slice(SLIDER)] = (L1 + L2, 0.0, 0.0)
    q0 = ideal.assemble(q0, 0.0)
    qd0 = ideal.velocities(q0, 0.0)
    if system.n != ideal.n:
        raise ValueError("system is not a slider-crank built by build()")
    return q0, qd0


def slider_crank_observer(system: System):
    """observe(q, qd, qdd, lam, t): crank angle, slider position/velocity/acceleration, crank moment (SI)."""
    crank, slider = system.slice(CRANK), system.slice(SLIDER)

    def observe(q, qd, qdd, lam, t):
        return {"crank_angle": float(q[crank.start + 2]), "slider_x": float(q[slider.start]),
                "slider_v": float(qd[slider.start]), "slider_a": float(qdd[slider.start]),
                "crank_moment": system.driving_moment(lam, "crank_driver")}
    # the same observables as linear picks (column, source, index, scale) for the compiled recorder
    observe.probes = (("crank_angle", "q", crank.start + 2, 1.0), ("slider_x", "q", slider.start, 1.0),
                      ("slider_v", "qd", slider.start, 1.0), ("slider_a", "qdd", slider.start, 1.0),
                      ("crank_moment", "lam", system.rows("crank_driver").start, -1.0))
    return observe


def ideal_reaction(system: System):
    """The ideal crank-rod pin's force on the crank (the housing body) from eq. (7), as (F_x, F_y) [N]."""
    crank = system.slice(CRANK)

    def reaction(q, lam):
        Qc = system.reactions(q, lam)["crank_rod"]
        return float(Qc[crank.start]), float(Qc[crank.start + 1])
    rows = system.rows("crank_rod")
    reaction.probe = (rows.start, rows.stop, crank.start, crank.start + 1)   # the same, for the compiled recorder
    return reaction
