"""The BallBearing FMU in libcosim (libcosimpy) and in ecos (ecospy), driven from Python: set parameters,
press the journal 20 µm along x with the inner ring at 1200 rpm, step 10 times, read the force. Both
engines load the FMU through its C API; in a Python process the interpreter is already there for
pythonfmu's binary (a native host needs the loader, docs/fmu-interface.md).

    python examples/fmu_in_libcosim_and_ecos.py [--short] [--tool libcosim|ecos]
"""
import sys

from _common import fmu, short

STEP, STEPS = 1e-5, 10 if short() else 100
E_X, OMEGA = 2e-5, 1200 * 2 * 3.141592653589793 / 60


def with_libcosim(path: str) -> tuple[float, float]:
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave
    log_output_level(CosimLogLevel.ERROR)
    execution = CosimExecution.from_step_size(step_size=int(round(STEP * 1e9)))     # libcosim counts ns
    bearing = execution.add_local_slave(CosimLocalSlave(fmu_path=path, instance_name="bearing"))
    vr = {v.name.decode(): v.reference for v in execution.slave_variables(slave_index=bearing)}
    execution.integer_initial_value(bearing, vr["n_balls"], 8)
    execution.real_initial_value(bearing, vr["damping_coefficient"], 50.0)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer=observer)
    manipulator = CosimManipulator.create_override()
    execution.add_manipulator(manipulator=manipulator)
    manipulator.slave_real_values(bearing, [vr["e_x"], vr["omega_inner"]], [E_X, OMEGA])
    if not execution.step(step_count=STEPS):
        raise RuntimeError("libcosim: a step failed")
    return tuple(observer.last_real_values(slave_index=bearing, variable_references=[vr["F_x"], vr["F_y"]]))


def with_ecos(path: str) -> tuple[float, float]:
    from ecospy import EcosSimulation, EcosSimulationStructure
    from ecospy.lib import EcosLib
    EcosLib.set_log_level("err")
    with EcosSimulationStructure() as ss:
        ss.add_model("bearing", path)
        ss.add_parameter_set("table2", {"bearing::n_balls": 8, "bearing::damping_coefficient": 50.0})
        with EcosSimulation(structure=ss, step_size=STEP) as sim:
            sim.init(parameter_set="table2")
            sim.set_real("bearing::e_x", E_X)
            sim.set_real("bearing::omega_inner", OMEGA)
            sim.step(STEPS)
            force = sim.get_real("bearing::F_x"), sim.get_real("bearing::F_y")
            sim.terminate()
    return force


if __name__ == "__main__":
    tools = {"libcosim": with_libcosim, "ecos": with_ecos}
    chosen = [sys.argv[sys.argv.index("--tool") + 1]] if "--tool" in sys.argv else list(tools)
    path = str(fmu())
    forces = {}
    for name in chosen:
        forces[name] = tools[name](path)
        print(f"{name}: after {STEPS} steps of {STEP:g} s at e_x = {E_X * 1e6:g} µm: "
              f"F = ({forces[name][0]:.2f}, {forces[name][1]:.2f}) N")
    # F is the force on the housing (outer ring): along the journal's displacement, +x here
    assert all(f[0] > 0 for f in forces.values())
    if len(forces) == 2:
        a, b = forces.values()
        assert abs(a[0] - b[0]) <= 1e-9 * abs(a[0]), "the two engines disagree"
