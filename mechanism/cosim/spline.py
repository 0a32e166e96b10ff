"""Not-a-knot cubic spline interpolation without importing scipy.interpolate (issue 11: ~22 MB of a run's peak).

``NotAKnotSpline(x, y)(x_new)`` gives the same numbers as ``scipy.interpolate.CubicSpline(x, y)(x_new)``
(default not-a-knot ends, extrapolating) bit for bit: the same tridiagonal system for the knot slopes,
solved by the same elimination as LAPACK's ``dgtsv`` (scipy's ``solve_banded`` for one lower and one upper
diagonal), the same Hermite coefficients and the same power-sum evaluation as scipy's ``PPoly``
(``tests/test_spline.py`` holds it against scipy). ``y`` may have several columns (one spline each).
Fewer than 4 knots (scipy's special cases) are scipy's: ``NotAKnotSpline`` then delegates to it.
"""
from __future__ import annotations

import numpy as np

#: rows evaluated at a time by ``NotAKnotSpline.evaluate_into`` (bounds the evaluation's temporaries)
EVAL_CHUNK_ROWS = 2048


def _slopes(x: np.ndarray, dx: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The knot slopes of the not-a-knot spline through (x, y) (n >= 4 knots, ``y`` of shape (n, m)):
    scipy's ``CubicSpline`` system (banded rows: upper, diagonal, lower), solved as ``dgtsv`` does."""
    n = len(x)
    dxr = dx[:, None]
    slope = np.diff(y, axis=0) / dxr
    d = np.empty(n)
    d[1:-1] = 2 * (dx[:-1] + dx[1:])
    du = np.empty(n - 1)
    du[1:] = dx[:-1]
    dl = np.empty(n - 1)
    dl[:-1] = dx[1:]
    b = np.empty_like(y)
    b[1:-1] = 3 * (dxr[1:] * slope[:-1] + dxr[:-1] * slope[1:])
    d[0] = dx[1]                       # not-a-knot at the start
    du[0] = x[2] - x[0]
    h = x[2] - x[0]
    b[0] = ((dxr[0] + 2 * h) * dxr[1] * slope[0] + dxr[0] ** 2 * slope[1]) / h
    d[-1] = dx[-2]                     # not-a-knot at the end
    dl[-1] = x[-1] - x[-3]
    h = x[-1] - x[-3]
    b[-1] = (dxr[-1] ** 2 * slope[-2] + (2 * h + dxr[-1]) * dxr[-2] * slope[-1]) / h
    # dgtsv: Gaussian elimination with partial pivoting (row interchanges; they depend on x alone), then the
    # back substitution, column by column on Python floats (IEEE doubles, the same operations in the same order)
    d, du, dl = d.tolist(), du.tolist(), dl.tolist()
    swap, fact = [False] * (n - 1), [0.0] * (n - 1)
    for i in range(n - 1):
        if abs(d[i]) >= abs(dl[i]):
            if d[i] == 0.0:
                raise np.linalg.LinAlgError("singular spline system (repeated knots?)")
            fact[i] = dl[i] / d[i]
            d[i + 1] = d[i + 1] - fact[i] * du[i]
            if i < n - 2:
                dl[i] = 0.0
        else:
            swap[i] = True
            fact[i] = d[i] / dl[i]
            d[i] = dl[i]
            temp = d[i + 1]
            d[i + 1] = du[i] - fact[i] * temp
            if i < n - 2:
                dl[i] = du[i + 1]
                du[i + 1] = -fact[i] * dl[i]
            du[i] = temp
    if d[n - 1] == 0.0:
        raise np.linalg.LinAlgError("singular spline system (repeated knots?)")
    for j in range(b.shape[1]):
        col = b[:, j].tolist()
        for i in range(n - 1):
            if swap[i]:
                col[i], col[i + 1] = col[i + 1], col[i] - fact[i] * col[i + 1]
            else:
                col[i + 1] = col[i + 1] - fact[i] * col[i]
        col[n - 1] = col[n - 1] / d[n - 1]
        col[n - 2] = (col[n - 2] - du[n - 2] * col[n - 1]) / d[n - 2]
        for i in range(n - 3, -1, -1):
            col[i] = (col[i] - du[i] * col[i + 1] - dl[i] * col[i + 2]) / d[i]
        b[:, j] = col
    return b


class NotAKnotSpline:
    """The not-a-knot cubic spline through (x, y): ``y`` of shape (n,) or (n, m), ``x`` strictly increasing."""

    def __init__(self, x: np.ndarray, y: np.ndarray, lazy: bool = False):
        """``lazy``: keep the knot slopes (n x m) and ``y`` (not copied) instead of the coefficients (4 x n x m), and
        make each evaluated interval's coefficients when it is evaluated (the same operations: the same bits)."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        self.vector = y.ndim == 1
        y2 = y.reshape(len(y), -1)
        if x.ndim != 1 or len(x) != len(y2):
            raise ValueError("x must be 1-D with one value per row of y")
        dx = np.diff(x)
        if len(x) < 2 or not np.all(dx > 0):
            raise ValueError("x must have at least 2 strictly increasing values")
        self.x = x
        self._scipy = None
        if len(x) < 4:   # scipy's special cases (a line, a parabola): few rows, scipy's own code
            from scipy.interpolate import CubicSpline
            self._scipy = CubicSpline(x, y2)
            self.c = None
            return
        s = _slopes(x, dx, y2)
        self._lazy = (y2, dx, s) if lazy else None
        self.m = y2.shape[1]
        if lazy:
            self.c = None
            return
        dxr = dx[:, None]
        slope = np.diff(y2, axis=0) / dxr          # CubicHermiteSpline's coefficients
        t = (s[:-1] + s[1:] - 2 * slope) / dxr
        self.c = np.stack((t / dxr, (slope - s[:-1]) / dxr - t, s[:-1], y2[:-1]))

    def evaluate_into(self, x_new: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The spline at ``x_new`` written into ``out`` (shape (len(x_new), m)), in chunks of rows."""
        x_new = np.asarray(x_new, dtype=float)
        if self._scipy is not None:
            out[...] = self._scipy(x_new)
            return out
        last = len(self.x) - 2
        for k in range(0, len(x_new), EVAL_CHUNK_ROWS):
            xs = x_new[k:k + EVAL_CHUNK_ROWS]
            i = np.clip(np.searchsorted(self.x, xs, side="right") - 1, 0, last)   # PPoly's interval: x_i <= x < x_i+1
            s = (xs - self.x[i])[:, None]
            c = self.c[:, i] if self._lazy is None else self._coefficients(i)
            z = s                  # PPoly's power sum: 0 + c3 + c2 s + c1 s^2 + c0 s^3, powers by repeated products
            res = 0.0 + c[3]
            res += c[2] * z
            z = z * s
            res += c[1] * z
            z = z * s
            res += c[0] * z
            out[k:k + len(xs)] = res
        return out

    def _coefficients(self, i: np.ndarray) -> np.ndarray:
        """A lazy spline's coefficients of the intervals ``i`` (``__init__``'s operations on those rows)."""
        y2, dx, s = self._lazy
        dxr = dx[i][:, None]
        slope = (y2[i + 1] - y2[i]) / dxr
        t = (s[i] + s[i + 1] - 2 * slope) / dxr
        return np.stack((t / dxr, (slope - s[i]) / dxr - t, s[i], y2[i]))

    def __call__(self, x_new: np.ndarray) -> np.ndarray:
        x_new = np.asarray(x_new, dtype=float)
        out = np.empty((len(x_new), self.m if self._scipy is None else self._scipy.c.shape[2]))
        self.evaluate_into(x_new, out)
        return out[:, 0] if self.vector else out
