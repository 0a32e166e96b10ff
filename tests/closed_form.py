"""Closed-form kinematics and inverse dynamics of an ideal slider-crank.

Independent of the ``mechanism`` package (do not import it here). Geometry: crank of
length r pivoted at the origin, crank angle theta = omega t (constant omega),
connecting rod of length l from the crank pin A to the slider pin B on the x axis,
centres of mass at mid-length, slider of mass m3 moving along x. No gravity.
All functions accept real or complex theta (complex for complex-step derivatives).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Crank:
    """Data of the ideal slider-crank [m, kg, kg m^2, rad/s]."""

    r: float
    l: float
    m1: float
    J1: float
    m2: float
    J2: float
    m3: float
    omega: float


def slider_x(c: Crank, theta):
    """Slider position x = r cos(theta) + sqrt(l^2 - r^2 sin^2(theta)) [m]."""
    s = np.sin(theta)
    return c.r * np.cos(theta) + np.sqrt(c.l ** 2 - c.r ** 2 * s ** 2)


def slider_xd(c: Crank, theta):
    """dx/dt [m/s], analytic."""
    s, co = np.sin(theta), np.cos(theta)
    root = np.sqrt(c.l ** 2 - c.r ** 2 * s ** 2)
    return -c.r * c.omega * s - c.r ** 2 * c.omega * s * co / root


def slider_xdd(c: Crank, theta):
    """d2x/dt2 [m/s^2], analytic."""
    s, co = np.sin(theta), np.cos(theta)
    root = np.sqrt(c.l ** 2 - c.r ** 2 * s ** 2)
    w2 = c.omega ** 2
    return (-c.r * w2 * co - c.r ** 2 * w2 * (co ** 2 - s ** 2) / root
            - c.r ** 4 * w2 * s ** 2 * co ** 2 / root ** 3)


def rod_angle(c: Crank, theta):
    """Rod angle phi from A to B, with l sin(phi) = -r sin(theta) [rad]."""
    return np.arcsin(-c.r * np.sin(theta) / c.l)


def rod_rates(c: Crank, theta):
    """(phi_dot [rad/s], phi_ddot [rad/s^2]) from l cos(phi) phi_dot = -r omega cos(theta)."""
    s, co = np.sin(theta), np.cos(theta)
    sphi = -c.r * s / c.l
    cphi = np.sqrt(1.0 - sphi ** 2)
    phid = -c.r * c.omega * co / (c.l * cphi)
    phidd = (c.r * c.omega ** 2 * s + c.l * sphi * phid ** 2) / (c.l * cphi)
    return phid, phidd


def centres(c: Crank, theta: float):
    """Centre-of-mass positions (crank, rod, slider) as complex numbers x + i y [m]; real theta."""
    pin = c.r * np.exp(1j * theta)
    return 0.5 * pin, 0.5 * (pin + slider_x(c, theta)), slider_x(c, theta) + 0j


def velocities(c: Crank, theta):
    """Centre-of-mass velocities (v1, v2, v3) as pairs (vx, vy) [m/s]; analytic in theta."""
    s, co = np.sin(theta), np.cos(theta)
    v_pin = (-c.r * c.omega * s, c.r * c.omega * co)
    xd = slider_xd(c, theta)
    v1 = (0.5 * v_pin[0], 0.5 * v_pin[1])
    v2 = (0.5 * (v_pin[0] + xd), 0.5 * v_pin[1])       # rod centre is the mid-point of A and B
    v3 = (xd, 0.0 * xd)
    return v1, v2, v3


def accelerations(c: Crank, theta: float):
    """Centre-of-mass accelerations (a1, a2, a3) as complex numbers [m/s^2]; real theta."""
    a_pin = -c.r * c.omega ** 2 * np.exp(1j * theta)
    xdd = slider_xdd(c, theta)
    return 0.5 * a_pin, 0.5 * (a_pin + xdd), xdd + 0j


def kinetic_energy(c: Crank, theta):
    """Total kinetic energy T(theta) [J] at constant omega (analytic in theta)."""
    v1, v2, v3 = velocities(c, theta)
    phid, _ = rod_rates(c, theta)
    return 0.5 * (c.J1 * c.omega ** 2 + c.J2 * phid ** 2
                  + c.m1 * (v1[0] ** 2 + v1[1] ** 2)
                  + c.m2 * (v2[0] ** 2 + v2[1] ** 2)
                  + c.m3 * (v3[0] ** 2 + v3[1] ** 2))


def crank_moment(c: Crank, theta, h: float = 1e-30):
    """Driving moment on the crank [N m] by power balance: M omega = dT/dt = omega dT/dtheta,
    so M = dT/dtheta, evaluated by complex step (exact to rounding)."""
    return np.imag(kinetic_energy(c, theta + 1j * h)) / h


def _cross(a: complex, b: complex) -> float:
    """z-component of the planar cross product of two complex-coded vectors."""
    return (np.conj(a) * b).imag


def newton_euler(c: Crank, theta: float) -> dict[str, complex | float]:
    """Joint forces by Newton-Euler equations of the three bodies (no gravity).

    Returns complex forces (x + i y) [N]: 'slider_from_rod' (force on the slider at B),
    'crank_from_ground' (force on the crank at O), 'rod_from_crank' (force on the rod
    at A); 'guide_normal' (y force of the guide on the slider) and 'moment' (driving
    moment on the crank, N m).
    """
    a1, a2, a3 = accelerations(c, theta)
    phi = rod_angle(c, theta)
    _, phidd = rod_rates(c, theta)
    e = np.exp(1j * phi)                                  # unit vector from A to B
    fbx = c.m3 * a3.real                                  # slider: m3 xdd = F_Bx
    # rod: m2 a2 = F_A - F_B, J2 phidd = -(l/2) e x (F_A + F_B)  ->  solve for F_By
    fby = ((-2.0 / c.l) * c.J2 * phidd - c.m2 * _cross(e, a2) + 2.0 * e.imag * fbx) / (2.0 * e.real)
    f_b = fbx + 1j * fby
    f_a = c.m2 * a2 + f_b
    # crank: m1 a1 = F_O - F_A; 0 = M + (O - c1) x F_O + (A - c1) x (-F_A)
    f_o = c.m1 * a1 + f_a
    c1 = 0.5 * c.r * np.exp(1j * theta)
    a_pt = c.r * np.exp(1j * theta)
    moment = -_cross(-c1, f_o) + _cross(a_pt - c1, f_a)
    return {"slider_from_rod": f_b, "crank_from_ground": f_o, "rod_from_crank": f_a,
            "guide_normal": -fby, "moment": moment}
