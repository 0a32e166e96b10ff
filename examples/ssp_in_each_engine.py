"""The whole system as SSP (SliderCrankBearing.ssp: the SliderCrank and BallBearing FMUs, their
connections and parameter sets) in each FMI engine: fmpy.ssp, libcosim and ecos, then our own master on
the same archive. Packs the archive first (into results/examples/).

    python examples/ssp_in_each_engine.py [--short]
"""
import subprocess
import sys

import numpy as np

from _common import ROOT, short

from mechanism.ssp.tools import TOOLS, simulate_with   # noqa: E402

# pack a fresh archive (the FMUs are rebuilt only when their sources changed): an archive left in dist/ by
# an older checkout may hold other FMUs or parameter sets
archive = ROOT / "results" / "examples" / "SliderCrankBearing.ssp"
subprocess.run([sys.executable, "-m", "mechanism", "ssp-pack", "--out", str(archive), "--fmu-dir", str(ROOT / "dist")],
               check=True, cwd=ROOT)
t_end = 0.002 if short() else 0.02          # s (1200 rpm: 0.05 s per revolution)
peaks = {}
for tool in TOOLS:
    r = simulate_with(tool, archive, step=1e-5, t_end=t_end)
    peaks[tool] = float(np.max(np.hypot(r["bearing.F_x"], r["bearing.F_y"])))
    print(f"{tool:8s}: {len(r['time'])} steps to {t_end:g} s, peak |F| = {peaks[tool]:.2f} N, "
          f"max |e| = {np.max(np.hypot(r['mechanism.e_x'], r['mechanism.e_y'])) * 1e6:.3f} µm")
# our master on the same archive and parameter set (the mechanism in-process, the BallBearing FMU from the archive)
subprocess.run([sys.executable, "-m", "mechanism", "run", "--ssp", str(archive), "--revs", str(t_end / 0.05),
                "--no-ideal", "--no-plots", "--quiet", "--out", str(ROOT / "results" / "examples" / "ssp_master")],
               check=True, cwd=ROOT)
# the three engines run the same Jacobi scheme on the same FMUs: libcosim and ecos agree to rounding
assert abs(peaks["libcosim"] - peaks["ecos"]) <= 1e-6 * peaks["ecos"]
