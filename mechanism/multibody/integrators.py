"""Fixed-step explicit integrators for first-order systems y' = f(t, y)."""
from __future__ import annotations

from typing import Callable

import numpy as np


def rk4_step(f: Callable[[float, np.ndarray], np.ndarray], t: float, y: np.ndarray,
             h: float) -> np.ndarray:
    """One classical 4th-order Runge-Kutta step of size h [s]; returns y(t + h).

    y is the concatenated state [q, qd]; f(t, y) returns dy/dt = [qd, qdd].
    """
    h2 = 0.5 * h
    k1 = f(t, y)
    k2 = f(t + h2, y + h2 * k1)
    k3 = f(t + h2, y + h2 * k2)
    k4 = f(t + h, y + h * k3)
    return y + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
