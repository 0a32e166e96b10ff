"""The master's Python API for your own mechanism: a four-bar linkage whose crank-coupler joint is the
ball bearing (the BallBearing FMU), built from ``mechanism.multibody.model`` data and co-simulated by
``mechanism.cosim.master.run_master`` — the same pieces ``mechanism/run.py`` puts together for the paper's
slider-crank.

    python examples/four_bar_with_bearing.py [--short]
"""
import math

import numpy as np

from _common import fmu, short

from mechanism.cosim.endpoints import FmuEndpoint                       # noqa: E402
from mechanism.cosim.joint import BearingLink                           # noqa: E402
from mechanism.cosim.master import MasterSettings, run_master           # noqa: E402
from mechanism.multibody.model import (GROUND, AngleDriver, BearingJoint, Body, Model, Point,  # noqa: E402
                                       Revolute)
from mechanism.multibody.solver import System                           # noqa: E402

# geometry [m], masses [kg], inertias [kg m^2]: ground pivots A = (0, 0) and D = (0.10, 0)
CRANK, COUPLER, ROCKER = 0.03, 0.10, 0.08
RPM = 600.0
OMEGA = RPM * 2 * math.pi / 60


def build(bearing: bool) -> Model:
    """The four-bar as data; the crank-coupler joint a bearing (force joint) or an ideal revolute."""
    bodies = (Body("crank", 0.2, 2e-5), Body("coupler", 0.3, 2.5e-4), Body("rocker", 0.25, 1.3e-4))
    on_crank, on_coupler = Point("crank", (CRANK / 2, 0.0)), Point("coupler", (-COUPLER / 2, 0.0))
    joints = [Revolute("A", Point(GROUND, (0.0, 0.0)), Point("crank", (-CRANK / 2, 0.0))),
              AngleDriver("drive", "crank", omega=OMEGA, theta0=0.0),
              Revolute("C", Point("coupler", (COUPLER / 2, 0.0)), Point("rocker", (ROCKER / 2, 0.0))),
              Revolute("D", Point(GROUND, (0.10, 0.0)), Point("rocker", (-ROCKER / 2, 0.0)))]
    bearings = ()
    if bearing:   # housing (outer ring) on the crank, journal (inner ring) on the coupler; Table 2's radii
        bearings = (BearingJoint("B", on_crank, on_coupler, housing_radius=0.026, journal_radius=0.012),)
    else:
        joints.append(Revolute("B", on_crank, on_coupler))
    return Model(bodies=bodies, joints=tuple(joints), bearings=bearings)


def initial_state(system: System) -> tuple[np.ndarray, np.ndarray]:
    """Assemble the ideal linkage at crank angle 0 (B = (0.03, 0), C above the ground line) and take its
    positions and velocities: the journal starts centred in the bearing."""
    ideal = System(build(bearing=False))
    b, d = np.array([CRANK, 0.0]), np.array([0.10, 0.0])
    # C on the circles |C - B| = COUPLER and |C - D| = ROCKER (the upper intersection)
    dist = np.linalg.norm(d - b)
    a = (COUPLER ** 2 - ROCKER ** 2 + dist ** 2) / (2 * dist)
    c = b + a * (d - b) / dist + math.sqrt(COUPLER ** 2 - a ** 2) * np.array([0.0, 1.0])
    q = np.zeros(ideal.n)
    q[ideal.slice("crank")] = (*(b / 2), 0.0)
    q[ideal.slice("coupler")] = (*((b + c) / 2), math.atan2(*(c - b)[::-1]))
    q[ideal.slice("rocker")] = (*((c + d) / 2), math.atan2(*(c - d)[::-1]))
    q = ideal.assemble(q, 0.0)
    if system.n != ideal.n:
        raise ValueError("the bearing and ideal models must have the same bodies")
    return q, ideal.velocities(q, 0.0)


def main() -> None:
    model = build(bearing=True)
    system = System(model)
    q0, qd0 = initial_state(system)
    def observe(q, qd, qdd, lam, t):
        """The quantities recorded each sample (SI). The master records the columns of
        mechanism.cosim.record.BASE_COLUMNS (and the component's); other names are not recorded yet."""
        return {"crank_angle": float(q[system.slice("crank").start + 2]),
                "crank_moment": system.driving_moment(lam, "drive")}

    revs = 0.1 if short() else 1.0
    settings = MasterSettings(t_end=revs * 60 / RPM, step=1e-5, output_interval=1e-4, progress=not short(),
                              description="four-bar")
    endpoint = FmuEndpoint(fmu(), {"n_balls": 8, "damping_coefficient": 50.0})
    try:
        result = run_master(system, q0, qd0, settings, observe, link=BearingLink(system, model.bearings[0]),
                            endpoint=endpoint)
    finally:
        endpoint.close()
    if not result.ok:
        raise SystemExit(f"the run failed: {result.message}")
    assert np.isclose(result["crank_angle"][-1], OMEGA * settings.t_end, rtol=1e-6)   # the driver held
    e = np.hypot(result["e_x"], result["e_y"]) * 1e6
    f = np.hypot(result["F_x"], result["F_y"])
    print(f"four-bar at {RPM:g} rpm, {revs:g} rev: max |e| = {e.max():.2f} µm, peak bearing force {f.max():.1f} N, "
          f"crank moment {result['crank_moment'].min():.3f} … {result['crank_moment'].max():.3f} N·m")


if __name__ == "__main__":
    main()
