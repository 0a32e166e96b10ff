"""A parameter variation with fmpy: the BallBearing FMU at a fixed eccentricity (the journal pressed
12 µm off centre, inner ring at 1200 rpm) for every radial clearance and ball count of a small grid;
prints the steady force and the largest ball load of each.

    python examples/parameter_variation.py [--short]
"""
import itertools

import numpy as np
from fmpy import simulate_fmu

from _common import fmu, short

clearances = [10e-6, 20e-6] if short() else [0.0, 10e-6, 20e-6, 30e-6]     # radial clearance P_d [m]
ball_counts = [8, 10] if short() else [6, 8, 10, 12]
t_end, h = 2e-4, 1e-5
path = str(fmu())

signals = np.array([(0.0, 12e-6, 0.0, 0.0, 0.0, 125.66, 0.0), (t_end, 12e-6, 0.0, 0.0, 0.0, 125.66, 0.0)],
                   dtype=[("time", float), ("e_x", float), ("e_y", float), ("v_x", float), ("v_y", float),
                          ("omega_inner", float), ("omega_outer", float)])
print(f"{'P_d [µm]':>9} {'balls':>5} {'|F| [N]':>9} {'max ball load [N]':>18} {'loaded':>6}")
for pd, n in itertools.product(clearances, ball_counts):
    r = simulate_fmu(path, stop_time=t_end, step_size=h, input=signals,
                     start_values={"radial_clearance": pd, "n_balls": n}, output=["F_x", "F_y", "max_ball_load",
                                                                                   "loaded_balls"])
    print(f"{pd * 1e6:9.0f} {n:5d} {np.hypot(r['F_x'][-1], r['F_y'][-1]):9.1f} {r['max_ball_load'][-1]:18.1f} "
          f"{int(r['loaded_balls'][-1]):6d}")
