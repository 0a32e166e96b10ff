"""A crank-rocker four-bar linkage as model data: a test model of the generic multibody core.

Bodies (coordinate order): "crank", "coupler", "rocker", each a slender bar with its centre of mass
at mid-length (inertia m L^2 / 12). Ground pivots O2 = (0, 0) and O4 = (ground_length, 0); joints:
ground-crank, crank-coupler, coupler-rocker and rocker-ground revolutes and a constant-speed crank
driver; with ``joint="bearing"`` the coupler-rocker pin is a ball bearing (force joint) instead.
The default lengths satisfy Grashof's condition (the crank turns fully). SI units.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mechanism.multibody.model import GROUND, AngleDriver, BearingJoint, Body, Model, Point, Revolute
from mechanism.multibody.solver import System


@dataclass(frozen=True)
class FourBarParameters:
    crank: float = 0.04          # m
    coupler: float = 0.12        # m
    rocker: float = 0.10         # m
    ground_length: float = 0.11  # m
    mass_per_length: float = 2.0  # kg/m
    rpm: float = 600.0
    gravity: float = 9.81        # m/s^2 along -y

    @property
    def omega(self) -> float:
        return self.rpm * 2.0 * math.pi / 60.0


def build(p: FourBarParameters = FourBarParameters(), joint: str = "ideal") -> Model:
    """The four-bar as a Model; ``joint`` = "ideal" or "bearing" (the coupler-rocker pin)."""
    bars = (("crank", p.crank), ("coupler", p.coupler), ("rocker", p.rocker))
    bodies = tuple(Body(name, p.mass_per_length * L, p.mass_per_length * L ** 3 / 12.0) for name, L in bars)
    half = {name: 0.5 * L for name, L in bars}
    joints = [Revolute("ground_crank", Point(GROUND, (0.0, 0.0)), Point("crank", (-half["crank"], 0.0))),
              AngleDriver("crank_driver", "crank", omega=p.omega, theta0=0.0),
              Revolute("crank_coupler", Point("crank", (half["crank"], 0.0)), Point("coupler", (-half["coupler"], 0.0))),
              Revolute("rocker_ground", Point("rocker", (-half["rocker"], 0.0)), Point(GROUND, (p.ground_length, 0.0)))]
    on_coupler, on_rocker = Point("coupler", (half["coupler"], 0.0)), Point("rocker", (half["rocker"], 0.0))
    bearings: tuple[BearingJoint, ...] = ()
    if joint == "ideal":
        joints.insert(3, Revolute("coupler_rocker", on_coupler, on_rocker))
    elif joint == "bearing":
        bearings = (BearingJoint("bearing", on_coupler, on_rocker, 0.026, 0.012),)
    else:
        raise ValueError(f"joint must be 'ideal' or 'bearing', not {joint!r}")
    return Model(bodies=bodies, joints=tuple(joints), bearings=bearings, gravity=(0.0, -p.gravity))


def initial_state(system: System, p: FourBarParameters = FourBarParameters()) -> tuple[np.ndarray, np.ndarray]:
    """Assembled positions at crank angle 0 (closed by the ideal four-bar's Newton assembly) and velocities."""
    ideal = System(build(p, "ideal"), system.alpha, system.beta)
    a, b, c, d = p.crank, p.coupler, p.rocker, p.ground_length
    # crank along +x; coupler end B on the circle about O4: intersect |B - A| = b, |B - O4| = c (upper branch)
    A = np.array([a, 0.0])
    O4 = np.array([d, 0.0])
    L = np.linalg.norm(O4 - A)
    x = (b * b - c * c + L * L) / (2 * L)
    h = math.sqrt(b * b - x * x)
    ex = (O4 - A) / L
    B = A + x * ex + h * np.array([-ex[1], ex[0]])
    th3 = math.atan2(*(B - A)[::-1])
    th4 = math.atan2(*(B - O4)[::-1])
    q = np.array([a / 2, 0.0, 0.0, *(A + (B - A) / 2), th3, *(O4 + (B - O4) / 2), th4])
    q = ideal.assemble(q, 0.0)
    return q, ideal.velocities(q, 0.0)
