"""Co-simulation cost per communication step against the FMU exchange it exists to perform (issue 11).

Prints, measured in one run (this machine is shared: compare the ratios, and run it more than once):

* the bare fmpy exchange on BallBearing.fmu: a loop of ``setReal`` (6 inputs) + ``doStep`` +
  ``getReal`` (8 coupling outputs) with prebuilt ctypes arrays, µs per call;
* the co-simulation loop (``python -m mechanism run``'s master with the FMU), µs per communication step,
  and its ratio to the bare exchange (target <= 3): the steps alone (the run's time less that of a 50-step run,
  i.e. without the run's fixed setup, as the bare exchange's loop is without the FMU's instantiation), and in
  brackets the whole run over its steps;
* the same loop with the force law in-process, µs per step (target <= 15 µs on the development machine);
* the same loop with the ideal joint (no bearing), µs per step;
* the wall time of the headline command ``python -m mechanism run`` (warm: the FMU built, the kernels
  compiled and cached; CSV and plots included; target <= 3 s) and its split: start-up and imports, the FMU
  run (loading kernels and FMU, then the loop), the ideal counterpart, the outputs (``cli.PHASES``); with
  ``--outputs-pair`` once more with the outputs drawn in-process (``MECHANISM_OUTPUT_WORKERS=0``);
* with ``--cold``, the wall time of the first run in a fresh numba cache (the compile, target <= 15 s).

Each loop figure is the median of ``--repeat`` runs, interleaved so that load changes hit them alike (a ratio: the
median of each repeat's loop over that repeat's exchange). Each target gets a verdict (``met`` / ``NOT met``), and
a last line names the targets missed.

    python benchmarks/cosim.py [--revs 2] [--rpm 1200] [--step 1e-5] [--repeat 3] [--cold] [--outputs-pair]
                               [--scheme NAME]

Runs against whatever ``mechanism`` is on the path (PYTHONPATH=<checkout> for a before/after pair;
``--cold`` needs the compiled master).
"""
from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mechanism import run as run_module
from mechanism.run import RunConfig, run


def bare_exchange_us(fmu: Path, calls: int = 10_000) -> float:
    """µs per setReal(6) + doStep + getReal(8) through fmpy's FMU2Slave with prebuilt ctypes arrays."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = extract(str(fmu))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="bench")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    names_in = ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")
    names_out = ("F_x", "F_y", "stiffness_xx", "stiffness_xy", "stiffness_yy", "damping_xx", "damping_xy",
                 "damping_yy")
    vr_in = (ctypes.c_uint * 6)(*(vr[n] for n in names_in))
    vr_out = (ctypes.c_uint * 8)(*(vr[n] for n in names_out if n in vr))
    val_in, val_out = (ctypes.c_double * 6)(), (ctypes.c_double * 8)()
    h, t = 1e-5, 0.0
    t0 = time.perf_counter()
    for k in range(calls):
        a = 0.01 * k
        val_in[0], val_in[1], val_in[2], val_in[3], val_in[4], val_in[5] = (
            3e-5 * math.cos(a), 3e-5 * math.sin(a), -0.01 * math.sin(a), 0.01 * math.cos(a), -52.0, 125.0)
        slave.fmi2SetReal(slave.component, vr_in, 6, val_in)
        slave.fmi2DoStep(slave.component, t, h, 1)
        slave.fmi2GetReal(slave.component, vr_out, len(vr_out), val_out)
        t += h
    us = (time.perf_counter() - t0) / calls * 1e6
    slave.terminate()
    slave.freeInstance()
    return us


#: the short run whose time is the run's fixed setup (FMU extraction and instantiation, its initialisation, the
#: model's build, the recorder): 0.01 revolution, 50 steps at the headline's 1200 rpm and 1e-5 s
SHORT_REVS = 0.01


def _steps(config: RunConfig) -> int:
    return round(config.revs * config.crank_period / config.step)


def _wall(config: RunConfig) -> float:
    t0 = time.perf_counter()
    result = run(config)
    wall = time.perf_counter() - t0
    assert result.ok, result.message
    return wall


def loop_us(config: RunConfig) -> tuple[float, float]:
    """µs per communication step of one run: (the whole run's wall time over its steps, setup included; the
    steps alone: the run's time less a ``SHORT_REVS`` run's, over the difference of their steps). The second is
    the figure the bare exchange compares with (its loop of calls leaves the FMU's instantiation out too); the
    setup is ~30 ms since the steps got fast, 3 µs per step of a 10,000-step run."""
    whole = _wall(config)
    short = RunConfig(**{**config.__dict__, "revs": SHORT_REVS})
    part = _wall(short)
    n, m = _steps(config), _steps(short)
    return whole * 1e6 / n, (whole - part) * 1e6 / (n - m)


#: the headline command as ``python -m mechanism run`` runs it (``mechanism/__main__.py``), then its phases (``cli.PHASES``) as JSON on the
#: last line of stderr
HEADLINE = ("import json, sys; from mechanism import cli; code = cli.main(sys.argv[1:]); "
            "print(json.dumps(cli.PHASES), file=sys.stderr); cli.exit_now(code)")


def headline(extra_env: dict | None = None) -> dict:
    """Wall seconds of the headline command (2 revolutions, CSV, ideal counterpart, plots) as a whole process,
    ``total``, and its split: ``run`` (the FMU run: loading the cached kernels and the FMU, then the master
    loop), ``ideal`` (the ideal-joint counterpart), ``outputs`` (CSV, summary.json and the plots, or waiting for
    the output worker drawing them), ``startup`` (the rest: the interpreter, every import, process exit)."""
    env = dict(os.environ, **(extra_env or {}))
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", HEADLINE, "run", "--quiet", "--out", out], check=True, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        total = time.perf_counter() - t0
    phases = json.loads(proc.stderr.strip().splitlines()[-1])
    split = {k: phases[k] for k in ("run", "ideal", "outputs")}
    return {"total": total, "startup": total - sum(split.values()), **split}


def headline_s(extra_env: dict | None = None) -> float:
    """Wall time [s] of ``python -m mechanism run`` (2 revolutions, CSV, ideal counterpart, plots)."""
    env = dict(os.environ, **(extra_env or {}))
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "mechanism", "run", "--quiet", "--out", out], check=True, env=env,
                       stdout=subprocess.DEVNULL)
        return time.perf_counter() - t0


def _verdict(value: float, limit: float) -> str:
    """"met" if value <= limit, else "NOT met" (one measurement, or the median of this run's repeats: the machine's
    speed drifts, run it again)."""
    return "met" if value <= limit else "NOT met"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--revs", type=float, default=2.0)
    p.add_argument("--rpm", type=float, default=1200.0)
    p.add_argument("--step", type=float, default=1e-5)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--cold", action="store_true", help="also time a first run in a fresh numba cache")
    p.add_argument("--outputs-pair", action="store_true",
                   help="also time the headline with its outputs in-process (MECHANISM_OUTPUT_WORKERS=0)")
    p.add_argument("--scheme", default=None, help="coupling scheme of the loops (default: the run's default)")
    a = p.parse_args()
    base = RunConfig(rpm=a.rpm, revs=a.revs, step=a.step, output_interval=a.step, progress=False,
                     **({"scheme": a.scheme} if a.scheme else {}))
    fmu = run_module.fmu_path(base)   # build the FMU before timing
    configs = {"cosim": base, "inprocess": RunConfig(**{**base.__dict__, "mode": "inprocess"}),
               "ideal": RunConfig(**{**base.__dict__, "joint": "ideal"})}
    for config in configs.values():   # warm up (imports, compiled kernels)
        run(RunConfig(**{**config.__dict__, "revs": 0.01}))
    samples: dict[str, list[float]] = {"bare": [], **{k: [] for k in configs}, **{k + " steps": [] for k in configs}}
    for _ in range(a.repeat):
        samples["bare"].append(bare_exchange_us(fmu))
        for name, config in configs.items():
            whole, steps_only = loop_us(config)
            samples[name].append(whole)
            samples[name + " steps"].append(steps_only)
    med = {k: statistics.median(v) for k, v in samples.items()}
    steps = round(a.revs * base.crank_period / a.step)
    print(f"{a.revs:g} revolutions at {a.rpm:g} rpm, step {a.step:g} s ({steps} communication steps), "
          f"scheme {base.scheme}, medians of {a.repeat}; per step: the steps alone (the run less a "
          f"{SHORT_REVS:g}-revolution run), [the whole run over its steps, setup included]; a ratio: the median of "
          f"each repeat's figure over that repeat's exchange")
    print(f"bare fmpy exchange (set 6, doStep, get 8)  {med['bare']:8.1f} µs/call")
    # each repeat's loop against the same repeat's exchange (the machine's speed drifts between repeats), their median
    ratio = {name: statistics.median(x / b for x, b in zip(samples[name + " steps"], samples["bare"]))
             for name in configs}
    verdicts = {"co-simulation loop <= 3 x the bare exchange": (ratio["cosim"], 3.0, "x"),
                "in-process loop <= 15 µs/step": (med["inprocess steps"], 15.0, "µs")}
    targets = {"cosim": f"x the bare exchange (target <= 3: {_verdict(ratio['cosim'], 3.0)})",
               "inprocess": f"x the bare exchange (target <= 15 µs/step: {_verdict(med['inprocess steps'], 15.0)})",
               "ideal": "x the bare exchange"}
    labels = {"cosim": "co-simulation loop (FMU)", "inprocess": "in-process loop (force law in-process)",
              "ideal": "ideal-joint loop (no bearing)"}
    whole = {name: statistics.median(x / b for x, b in zip(samples[name], samples["bare"])) for name in configs}
    for name in configs:
        print(f"{labels[name]:<42} {med[name + ' steps']:8.1f} µs/step   {ratio[name]:6.2f} "
              f"{targets[name]}   [{med[name]:.1f} µs/step, {whole[name]:.2f} x]")
    same = (a.revs, a.rpm, a.step, base.scheme) == (2.0, 1200.0, 1e-5, RunConfig().scheme)   # the headline's run
    for label, env in (("", None), *(("outputs in-process", {"MECHANISM_OUTPUT_WORKERS": "0"}),) * a.outputs_pair):
        h = headline(env)
        print(f"headline `python -m mechanism run` (warm)  {h['total']:8.2f} s (target <= 3 s: "
              f"{_verdict(h['total'], 3.0)})" + (f", {label}" if label else ""))
        if not label:
            verdicts["headline `python -m mechanism run` warm <= 3 s"] = (h["total"], 3.0, "s")
        print(f"  start-up and imports {h['startup']:.2f} s, FMU run {h['run']:.2f} s"
              + (f" (a warm run in this process: {med['cosim'] * steps * 1e-6:.2f} s)" if same else "")
              + f", ideal counterpart {h['ideal']:.2f} s, CSV + summary + plots {h['outputs']:.2f} s")
    if a.cold:
        with tempfile.TemporaryDirectory() as cache:
            cold = headline_s({"NUMBA_CACHE_DIR": cache})
            print(f"first run, fresh numba cache (compiling)   {cold:8.2f} s (target <= 15 s: {_verdict(cold, 15.0)})")
            verdicts["first run (fresh numba cache) <= 15 s"] = (cold, 15.0, "s")
    missed = [f"{name} ({value:.2f} {unit})" for name, (value, limit, unit) in verdicts.items() if value > limit]
    print(f"targets (this development machine's): {len(verdicts) - len(missed)} of {len(verdicts)} met"
          + (f"; not met: {'; '.join(missed)}" if missed else "")
          + ("" if same else " (the loop targets are set for the default scheme, 2 revolutions at 1200 rpm, 1e-5 s)"))


if __name__ == "__main__":
    main()
