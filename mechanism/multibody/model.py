"""A planar multibody model as plain data (Nikravesh style).

A :class:`Model` lists bodies, kinematic joints (constraints, eq. 3 of Xu et al. 2012)
and force joints (ball bearings, Section 3). It carries no behaviour: the generic
solver in :mod:`mechanism.multibody.solver` turns it into equations.

Units are SI throughout: m, kg, kg m^2, rad, rad/s, s, m/s^2.

Body coordinates are q_k = [x_k, y_k, theta_k] (eq. 1-2): the global position of the
centre of mass and the rotation of the body frame. Ground is the pseudo-body
:data:`GROUND`; it has no coordinates and its frame is the global frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

GROUND = "ground"
"""Name of the ground pseudo-body (fixed global frame, no coordinates)."""


@dataclass(frozen=True)
class Body:
    """A rigid planar body.

    mass: [kg]; inertia: polar moment of inertia about the centre of mass [kg m^2].
    """

    name: str
    mass: float
    inertia: float

    def __post_init__(self) -> None:
        if self.name == GROUND:
            raise ValueError(f"'{GROUND}' is reserved for the ground pseudo-body")
        if not (self.mass > 0.0 and self.inertia > 0.0):
            raise ValueError(f"body {self.name!r}: mass and inertia must be positive")


@dataclass(frozen=True)
class Point:
    """A point fixed on a body.

    local: coordinates [m] in the body frame, measured from the centre of mass;
    global coordinates when ``body == GROUND``.
    """

    body: str
    local: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class Revolute:
    """Ideal pin joint: Phi = r_j^P - r_i^P = 0 (2 equations: x, y)."""

    name: str
    i: Point
    j: Point


@dataclass(frozen=True)
class Translational:
    """Ideal prismatic joint: point j slides on the line through point i with direction
    ``axis`` (fixed in body i's frame); the relative rotation is locked.

    Phi = [ n_i . (r_j^P - r_i^P),  theta_j - theta_i - angle0 ]  (2 equations),
    with n_i the axis rotated by +90 deg; angle0 [rad] is the relative angle
    theta_j - theta_i of the assembled model.
    """

    name: str
    i: Point
    j: Point
    axis: tuple[float, float] = (1.0, 0.0)
    angle0: float = 0.0

    def __post_init__(self) -> None:
        if math.hypot(*self.axis) == 0.0:
            raise ValueError(f"translational joint {self.name!r}: axis must be non-zero")


@dataclass(frozen=True)
class AngleDriver:
    """Driving constraint Phi = theta - theta0 - omega t = 0 (eq. 3 with explicit time).

    omega [rad/s], theta0 [rad]. Its Lagrange multiplier gives the driving moment.
    """

    name: str
    body: str
    omega: float
    theta0: float = 0.0


@dataclass(frozen=True)
class BearingJoint:
    """A ball bearing as a *force* joint (Section 3): no constraint equation.

    housing: the outer-ring centre on body i; journal: the inner-ring centre on body j.
    housing_radius, journal_radius [m]: radii at which the contact forces act
    (eq. 13-15). The force itself is computed outside the solver.
    """

    name: str
    housing: Point
    journal: Point
    housing_radius: float
    journal_radius: float


Joint = Union[Revolute, Translational, AngleDriver]

N_EQUATIONS: dict[type, int] = {Revolute: 2, Translational: 2, AngleDriver: 1}
"""Number of constraint equations of each kinematic joint type."""


def joint_bodies(joint: Joint) -> tuple[str, ...]:
    """Names of the bodies (possibly GROUND) a kinematic joint connects."""
    if isinstance(joint, AngleDriver):
        return (joint.body,)
    return (joint.i.body, joint.j.body)


@dataclass(frozen=True)
class Model:
    """Bodies, kinematic joints, force joints and gravity [m/s^2] of a planar mechanism.

    The order of ``bodies`` fixes the coordinate order q = [x1, y1, th1, x2, ...];
    the order of ``joints`` fixes the order of the constraint equations.
    """

    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...] = ()
    bearings: tuple[BearingJoint, ...] = ()
    gravity: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        names = [b.name for b in self.bodies]
        if len(set(names)) != len(names):
            raise ValueError("body names must be unique")
        known = set(names) | {GROUND}
        element_names = [e.name for e in (*self.joints, *self.bearings)]
        if len(set(element_names)) != len(element_names):
            raise ValueError("joint and bearing names must be unique")
        for joint in self.joints:
            if type(joint) not in N_EQUATIONS:
                raise TypeError(f"unsupported joint type {type(joint).__name__}")
            _check_bodies(joint.name, joint_bodies(joint), known)
            if isinstance(joint, AngleDriver) and joint.body == GROUND:
                raise ValueError(f"driver {joint.name!r} cannot drive ground")
        for bearing in self.bearings:
            _check_bodies(bearing.name, (bearing.housing.body, bearing.journal.body), known)

    def body(self, name: str) -> Body:
        """The body called ``name``."""
        for b in self.bodies:
            if b.name == name:
                return b
        raise KeyError(name)

    def joint(self, name: str) -> Joint:
        """The kinematic joint called ``name``."""
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)


def _check_bodies(name: str, bodies: tuple[str, ...], known: set[str]) -> None:
    for b in bodies:
        if b not in known:
            raise ValueError(f"{name!r} refers to unknown body {b!r}")
    if len(bodies) == 2 and bodies[0] == bodies[1]:
        raise ValueError(f"{name!r} connects body {bodies[0]!r} to itself")
