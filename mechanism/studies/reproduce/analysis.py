"""Signal analysis of the cached runs: windows, ball loads and angles, RMS deviations, error patterns,
dominant frequencies, and the figures of merit of a run."""
from __future__ import annotations

import math

import numpy as np

from fmu_bearing.parameters import BearingParameters
from mechanism.cosim.record import RunResult
from mechanism.studies.reproduce.paper import (VIBRATION_MIN_HARMONIC)


def n_balls_of(r: RunResult) -> int:
    cfg = r.meta.get("config", {})
    n = cfg.get("balls") or cfg.get("settings", {}).get("n_balls")
    return int(n) if n else BearingParameters().n_balls


def half_clearance_of(r: RunResult) -> float:
    """Free play per side [m]: P_d/2 of the bearing, or the clearance joint's radial clearance."""
    if "clearance_per_side_m" in r.meta:
        return float(r.meta["clearance_per_side_m"])
    settings = r.meta.get("config", {}).get("settings", {})
    if r.meta.get("config", {}).get("joint") == "clearance":
        return float(settings.get("radial_clearance", 0.5 * BearingParameters().radial_clearance))
    return 0.5 * float(settings.get("radial_clearance", BearingParameters().radial_clearance))


def crank_period(r: RunResult) -> float:
    return float(r.meta.get("crank_period_s") or 60.0 / float(r.meta["config"]["rpm"]))


def window(r: RunResult) -> np.ndarray:
    """Analysis window: the second crank revolution if the run covers it, else the whole run."""
    t, T = r["time"], crank_period(r)
    tol = 0.5 * float(np.median(np.diff(t))) if len(t) > 1 else 0.0   # the last step may fall short of 2 T
    if len(t) and t[-1] >= 2 * T - tol - 1e-12:
        return (t >= T - tol) & (t <= 2 * T + tol)
    return np.ones_like(t, dtype=bool)


def rev_mask(r: RunResult, k: int) -> np.ndarray:
    t, T = r["time"], crank_period(r)
    tol = 0.5 * float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return (t >= (k - 1) * T - tol) & (t <= k * T + tol)


def on_times(ideal: RunResult, r: RunResult, column: str) -> np.ndarray:
    """The ideal run's ``column`` at the sample times of ``r``: its samples where the time grids agree,
    else a cubic spline through them (the ideal runs are smooth and sampled every 1e-4 s)."""
    t, ti = r["time"], ideal["time"]
    if len(t) <= len(ti) and np.allclose(t, ti[:len(t)], rtol=0, atol=1e-12):
        return ideal[column][:len(t)]
    from scipy.interpolate import CubicSpline
    return CubicSpline(ti, ideal[column])(t)   # extrapolates over the last step's overhang, if any


def eccentricity(r: RunResult) -> np.ndarray:
    return np.hypot(r["e_x"], r["e_y"])


def ball_loads(r: RunResult) -> np.ndarray:
    """(samples, N_b) loads of the run's balls [N]."""
    return np.column_stack([r[f"ball_load_{k + 1}"] for k in range(n_balls_of(r))])


def ball_angles(r: RunResult) -> np.ndarray:
    """(samples, N_b) ball angles phi_r = cage_angle + 2 pi (r - 1)/N_b [rad] (eq. 17, integrated cage)."""
    n = n_balls_of(r)
    return r["cage_angle"][:, None] + 2 * np.pi * np.arange(n)[None, :] / n


def ball_deflections(r: RunResult) -> np.ndarray:
    """(samples, N_b) e . u_r - P_d/2 [m] at the recorded eccentricity and cage angle."""
    phi = ball_angles(r)
    return r["e_x"][:, None] * np.cos(phi) + r["e_y"][:, None] * np.sin(phi) - half_clearance_of(r)


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else math.nan


def rms_deviation(r: RunResult, ideal: RunResult, column: str = "slider_a", mask: np.ndarray | None = None) -> float:
    """RMS of r[column] minus the ideal joint's at the same times, over ``mask`` (default: ``window``)."""
    m = window(r) if mask is None else mask
    return rms((r[column] - on_times(ideal, r, column))[m])


def smooth(x: np.ndarray, n: int) -> np.ndarray:
    """Moving average over n samples (edges padded with the end values)."""
    if n <= 1:
        return x
    pad = np.concatenate((np.full(n // 2, x[0]), x, np.full(n - 1 - n // 2, x[-1])))
    return np.convolve(pad, np.ones(n) / n, mode="valid")


def error_pattern(r: RunResult, err: np.ndarray) -> tuple[list[float], float]:
    """Where a slider position error is smallest and whether it is largest with the mechanism horizontal.

    Over ``window``, with ``err`` smoothed over 1/50 revolution: the crank angles (mod 2 pi, in pi
    rad) where it changes sign, and min over the horizontal positions (crank angle 0 and pi) of
    |err| there divided by max |err|.
    """
    m = window(r)
    per_rev = max(1, int(round(crank_period(r) / float(np.median(np.diff(r["time"]))))))
    e = smooth(err, max(1, per_rev // 50))[m]
    ang = np.mod(r["crank_angle"][m], 2 * np.pi) / np.pi
    idx = np.nonzero(np.sign(e[1:]) * np.sign(e[:-1]) < 0)[0]
    crossings: list[float] = []
    for x in ang[idx]:
        if not crossings or abs(x - crossings[-1]) > 0.05:
            crossings.append(float(x))
    peak = float(np.max(np.abs(e))) if len(e) else math.nan
    horiz = []
    for target in (0.0, 1.0):
        d = np.abs(np.angle(np.exp(1j * np.pi * (ang - target))))
        horiz.append(float(np.abs(e[np.argmin(d)])) / peak if peak > 0 else math.nan)
    return crossings, min(horiz)


def orbit_window(r: RunResult, start_revs: float = 0.25) -> tuple[np.ndarray, bool]:
    """Samples of one orbital period of the balls (the cage turning 2 pi) from ``start_revs`` crank
    revolutions on (after the start transient), or from the start if the run is too short; and
    whether the orbit is complete."""
    t, cage = r["time"], r["cage_angle"]
    t0 = start_revs * crank_period(r)
    k0 = int(np.searchsorted(t, t0))
    if k0 >= len(t) or cage[-1] - cage[k0] < 2 * np.pi:
        k0 = 0
    rel = cage - cage[k0]
    m = (np.arange(len(t)) >= k0) & (rel <= 2 * np.pi + 1e-12)
    return m, bool(rel[-1] >= 2 * np.pi)


def dominant_frequency(t: np.ndarray, x: np.ndarray, f_min: float = 0.0) -> float:
    """Frequency [Hz] of the largest FFT amplitude of x (mean removed, Hann window) above f_min."""
    if len(x) < 8:
        return math.nan
    dt = float(np.median(np.diff(t)))
    y = (x - np.mean(x)) * np.hanning(len(x))
    amp = np.abs(np.fft.rfft(y))
    f = np.fft.rfftfreq(len(x), dt)
    sel = f > f_min
    return float(f[sel][np.argmax(amp[sel])]) if sel.any() else math.nan


def vibration_frequency(r: RunResult, ideal: RunResult, column: str = "slider_a") -> float:
    """Dominant frequency of r[column] minus the ideal joint's (the contact vibration), above
    VIBRATION_MIN_HARMONIC times the crank frequency, over the whole run."""
    f_crank = 1.0 / crank_period(r)
    return dominant_frequency(r["time"], r[column] - on_times(ideal, r, column), VIBRATION_MIN_HARMONIC * f_crank)


def figures_of(r: RunResult, ideal: RunResult | None) -> dict:
    """The report's measured figures of one run over ``window`` (SI)."""
    m = window(r)
    out = {"max_e": float(np.max(eccentricity(r)[m])) if m.any() else math.nan,
           "peak_F": float(np.max(np.hypot(r["F_x"], r["F_y"])[m])) if m.any() else math.nan,
           "a_min": float(np.min(r["slider_a"][m])), "a_max": float(np.max(r["slider_a"][m])),
           "M_min": float(np.min(r["crank_moment"][m])), "M_max": float(np.max(r["crank_moment"][m])),
           "max_ball_load": math.nan, "rms_da": math.nan, "max_dx": math.nan, "rel_rms_da": math.nan}
    if r.has("cage_angle"):
        out["max_ball_load"] = float(np.max(ball_loads(r)[m]))
    if ideal is not None:
        out["rms_da"] = rms_deviation(r, ideal, "slider_a", m)
        out["rel_rms_da"] = out["rms_da"] / rms(on_times(ideal, r, "slider_a")[m])
        out["max_dx"] = float(np.max(np.abs(r["slider_x"] - on_times(ideal, r, "slider_x"))[m]))
    return out


# --- figure helpers ------------------------------------------------------------------------------------
