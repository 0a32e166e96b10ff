"""A double pendulum under gravity as model data: a test model of the generic multibody core.

Bodies "upper" and "lower", slender bars (centre of mass at mid-length, inertia m L^2 / 12); the
upper hangs from ground at the origin, the lower from the upper's free end; no driver (two
degrees of freedom), so the mechanism's energy is conserved. SI units.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mechanism.multibody.model import GROUND, Body, Model, Point, Revolute
from mechanism.multibody.solver import System


@dataclass(frozen=True)
class DoublePendulumParameters:
    upper: float = 0.3           # m
    lower: float = 0.2           # m
    mass_per_length: float = 1.5  # kg/m
    gravity: float = 9.81        # m/s^2 along -y
    angle_upper: float = 0.8     # rad, start angle of the upper bar from the downward vertical
    angle_lower: float = -0.4    # rad


def build(p: DoublePendulumParameters = DoublePendulumParameters()) -> Model:
    bodies = tuple(Body(name, p.mass_per_length * L, p.mass_per_length * L ** 3 / 12.0)
                   for name, L in (("upper", p.upper), ("lower", p.lower)))
    joints = (Revolute("pivot", Point(GROUND, (0.0, 0.0)), Point("upper", (-0.5 * p.upper, 0.0))),
              Revolute("elbow", Point("upper", (0.5 * p.upper, 0.0)), Point("lower", (-0.5 * p.lower, 0.0))))
    return Model(bodies=bodies, joints=joints, gravity=(0.0, -p.gravity))


def initial_state(system: System, p: DoublePendulumParameters = DoublePendulumParameters()
                  ) -> tuple[np.ndarray, np.ndarray]:
    """At rest, released from the given angles (bar axes from the downward vertical)."""
    th1, th2 = p.angle_upper - 0.5 * math.pi, p.angle_lower - 0.5 * math.pi
    c1 = 0.5 * p.upper * np.array([math.cos(th1), math.sin(th1)])
    end1 = 2 * c1
    c2 = end1 + 0.5 * p.lower * np.array([math.cos(th2), math.sin(th2)])
    q = system.assemble(np.array([*c1, th1, *c2, th2]), 0.0)
    return q, np.zeros(system.n)
