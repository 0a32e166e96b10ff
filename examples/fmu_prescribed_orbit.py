"""The BallBearing FMU on its own, driven by fmpy's simulate_fmu with an input table: the journal centre
follows a prescribed eccentricity orbit (a circle of radius 15 µm, turning at 20 Hz, while the inner ring
spins at 1200 rpm), and the FMU returns the bearing force and the ball loads.

    python examples/fmu_prescribed_orbit.py [--short]
"""
import numpy as np
from fmpy import simulate_fmu

from _common import fmu, short

R, F_ORBIT, OMEGA_INNER = 15e-6, 20.0, 1200 * 2 * np.pi / 60     # m, Hz, rad/s
t_end = 0.005 if short() else 0.05
h = 1e-5

# the input table: a structured array with "time" first, then one column per FMU input (SI)
t = np.arange(0.0, t_end + h / 2, h)
w = 2 * np.pi * F_ORBIT
signals = np.zeros(len(t), dtype=[("time", float), ("e_x", float), ("e_y", float), ("v_x", float), ("v_y", float),
                                  ("omega_inner", float), ("omega_outer", float)])
signals["time"] = t
signals["e_x"], signals["e_y"] = R * np.cos(w * t), R * np.sin(w * t)
signals["v_x"], signals["v_y"] = -R * w * np.sin(w * t), R * w * np.cos(w * t)
signals["omega_inner"] = OMEGA_INNER

result = simulate_fmu(str(fmu()), start_time=0.0, stop_time=t_end, step_size=h, output_interval=h,
                      input=signals, start_values={"n_balls": 8, "damping_coefficient": 50.0},
                      output=["F_x", "F_y", "loaded_balls", "max_ball_load"])

force = np.hypot(result["F_x"], result["F_y"])
print(f"{len(result)} samples to t = {result['time'][-1]:.4g} s: |F| {force.min():.1f} … {force.max():.1f} N, "
      f"up to {int(result['loaded_balls'].max())} balls loaded, max ball load {result['max_ball_load'].max():.1f} N")
# the radial clearance is 20 µm (10 µm per side): at |e| = 15 µm the journal presses 5 µm into the balls
assert force.max() > 0 and np.all(np.isfinite(force))
