"""Drive an FMU from the native C host ``host.c`` (a non-Python process): for tests and benchmarks.

``compile_host(folder)`` builds the host with zig cc; ``run_host(...)`` runs it on an extracted FMU with
a clean environment (no LD_PRELOAD, no PYTHONPATH, no PYTHONHOME) and parses what it prints.
"""
from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

from fmu_bearing.native.build import LoaderBuildError, zig_cc

HOST_SOURCE = Path(__file__).resolve().parent / "host.c"
INPUT_NAMES = ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")
OUTPUT_NAMES = ("F_x", "F_y")
#: environment variables a clean native run must not inherit
_UNCLEAN = ("LD_PRELOAD", "LD_LIBRARY_PATH", "PYTHONPATH", "PYTHONHOME", "BEARING_FMU_LIBPYTHON", "BEARING_FMU_PYTHON")


def compile_host(folder: str | Path) -> Path:
    """Compile ``host.c`` into ``folder/host`` (x86_64 Linux, glibc 2.17); LoaderBuildError without zig."""
    exe = Path(folder) / "host"
    command = [*zig_cc(), "-target", "x86_64-linux-gnu.2.17", "-O2", "-std=gnu99", "-o", str(exe),
               str(HOST_SOURCE), "-ldl", "-lpthread", "-lm"]
    proc = subprocess.run(command, capture_output=True, text=True)
    if proc.returncode != 0:
        raise LoaderBuildError(f"compiling the native test host failed:\n{proc.stderr}")
    return exe


def clean_env(**extra: str) -> dict[str, str]:
    """The current environment without the variables that would help the FMU find Python, plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if k not in _UNCLEAN and k != "VIRTUAL_ENV"}
    env.update(extra)
    return env


@dataclass
class HostRun:
    """What one host process did: exit status, per instance (F_x, F_y, sum F_x, sum F_y), cycle time."""

    returncode: int
    forces: list[tuple[float, float, float, float]]
    cycle_us: float | None
    stdout: str
    stderr: str


def host_command(host: Path, unzipdir: str | Path, n_instances: int = 1, n_steps: int = 1000,
                 mode: str = "seq") -> list[str]:
    """Command line of the host for the FMU extracted in ``unzipdir``."""
    unzipdir = Path(unzipdir).resolve()
    root = ElementTree.parse(unzipdir / "modelDescription.xml").getroot()
    vr = {v.get("name"): v.get("valueReference") for v in root.iter("ScalarVariable")}
    model_id = root.find("CoSimulation").get("modelIdentifier")
    binary = unzipdir / "binaries" / "linux64" / f"{model_id}.so"
    return [str(host), str(binary), (unzipdir / "resources").as_uri(), root.get("guid"), str(n_instances),
            str(n_steps), mode, ",".join(vr[n] for n in INPUT_NAMES), ",".join(vr[n] for n in OUTPUT_NAMES)]


def run_host(host: Path, unzipdir: str | Path, n_instances: int = 1, n_steps: int = 1000, mode: str = "seq",
             env: dict[str, str] | None = None, timeout: float = 120) -> HostRun:
    """Run the host once (clean environment unless ``env``) and parse its output."""
    proc = subprocess.run(host_command(host, unzipdir, n_instances, n_steps, mode),
                          env=clean_env() if env is None else env, capture_output=True, text=True, timeout=timeout)
    forces, cycle = [], None
    for line in proc.stdout.splitlines():
        parts = line.split()
        if parts[:1] == ["instance"]:
            forces.append(tuple(float(p) for p in parts[2:6]))
        elif parts[:1] == ["cycle_us"]:
            cycle = float(parts[1])
    return HostRun(proc.returncode, forces, cycle, proc.stdout, proc.stderr)


def reference_forces(unzipdir: str | Path, n_steps: int = 1000) -> tuple[float, float, float, float]:
    """The host's input sequence through fmpy in this process: (F_x, F_y, sum F_x, sum F_y)."""
    import math

    from fmpy import read_model_description
    from fmpy.fmi2 import FMU2Slave

    unzipdir = str(Path(unzipdir).resolve())
    md = read_model_description(unzipdir)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="reference")
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        ins, outs = [vr[n] for n in INPUT_NAMES], [vr[n] for n in OUTPUT_NAMES]
        h, sums, y = 1e-5, [0.0, 0.0], [0.0, 0.0]
        for i in range(n_steps):
            a = 2 * math.pi * (i % 64) / 64.0
            fmu.setReal(ins, [3e-5 * math.cos(a), 3e-5 * math.sin(a), -0.01 * math.sin(a), 0.01 * math.cos(a),
                              100.0, 0.0])
            fmu.doStep(i * h, h)
            y = fmu.getReal(outs)
            sums[0] += y[0]
            sums[1] += y[1]
        fmu.terminate()
    finally:
        fmu.freeInstance()
    return y[0], y[1], sums[0], sums[1]


if __name__ == "__main__":  # python -m fmu_bearing.native.host FOLDER: compile the host there
    print(compile_host(sys.argv[1] if len(sys.argv) > 1 else "."))
