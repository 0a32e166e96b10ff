"""Fuzz suite (issue 14): seeded, reproducible malformed parameters, inputs, FMU states, SSP archives and
command lines. Every case must end in an error status (FMU) or an error/non-zero exit (SSP reader, CLI)
whose message names the cause, and no case may crash its host.

Cases run in batches in subprocesses (``python tests/test_fuzz.py FMU SSP < cases.json``, one JSON
result line per case), two batches at a time; if a batch process dies, its unfinished cases are rerun
one per process, so a crash fails the case that caused it (and names it) instead of killing pytest.
``FUZZ_SEED`` (default 14) chooses the cases; the same seed gives the same cases.
"""
from __future__ import annotations

import json
import math
import os
import random
import subprocess
import sys
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SEED = int(os.environ.get("FUZZ_SEED", "14"))
BATCH = 150
#: number of cases per category (>= 1,000 in all)
COUNTS = {"parameter": 240, "input": 220, "state": 220, "crank_state": 120, "ssp": 110, "cli": 120}
INPUTS = ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")
GOOD_INPUTS = (1.2e-5, -0.4e-5, 1e-3, 0.0, 125.0, 0.0)
BAD_REALS = (math.nan, math.inf, -math.inf, 1e300, -1e300)


# ------------------------------------------------------------------------------------------ cases
def parameter_cases(rng: random.Random, n: int, variables: dict) -> list[dict]:
    """A start value out of the parameter's documented range, of the wrong FMI type, or an unknown
    value reference, set before initialisation."""
    from fmu_bearing.parameters import RANGES
    params = [name for name, v in variables.items() if v["causality"] == "parameter"]
    cases = []
    while len(cases) < n:
        name = rng.choice(params)
        kind = variables[name]["type"]
        lo, hi = RANGES.get(name, (None, None))
        pick = rng.random()
        if pick < 0.08:
            cases.append({"kind": "parameter", "name": name, "vr": 900000 + rng.randrange(1000),
                          "as": "Real", "value": 1.0, "expect": "valueReference"})
            continue
        if kind == "Real":
            if pick < 0.25:   # wrong FMI type for the variable
                cases.append({"kind": "parameter", "name": name, "as": "Integer", "value": rng.randrange(-5, 5),
                              "expect": name})
                continue
            choices = list(BAD_REALS)
            if hi is not None and math.isfinite(hi):
                choices.append(hi * (1 + rng.uniform(0.01, 100)) + 1e-12)
            if lo is not None and math.isfinite(lo) and lo >= 0:
                choices.append(-rng.uniform(1e-9, 1e3) - lo)
            value = rng.choice(choices)
        elif kind == "Integer":
            if pick < 0.4:   # a non-integer through setReal: the FMU must not truncate it
                cases.append({"kind": "parameter", "name": name, "as": "Real",
                              "value": rng.randrange(0, 9) + rng.uniform(0.01, 0.99), "expect": name})
                continue
            value = rng.choice([hi + rng.randrange(1, 10**6), lo - rng.randrange(1, 10**6), 2**31 - 1, -2**31,
                                hi + 1, lo - 1])
        else:  # Boolean: only through another type
            kind = rng.choice(["Real", "Integer"])
            cases.append({"kind": "parameter", "name": name, "as": kind,
                          "value": rng.choice([0.5, 2.0, -1.0, math.nan] if kind == "Real" else [2, -1, 7]),
                          "expect": name})
            continue
        cases.append({"kind": "parameter", "name": name, "as": kind, "value": value, "expect": name})
    return cases


def input_cases(rng: random.Random, n: int) -> list[dict]:
    """After a valid initialisation: one input non-finite or the eccentricity beyond the limit, or a
    bad step size, then doStep."""
    cases = []
    while len(cases) < n:
        inputs = list(GOOD_INPUTS)
        pick = rng.random()
        step = 1e-5
        if pick < 0.5:
            k = rng.randrange(6)
            inputs[k] = rng.choice([math.nan, math.inf, -math.inf])
            expect = INPUTS[k]
        elif pick < 0.8:
            r, a = 10 ** rng.uniform(math.log10(5e-4), 300), rng.uniform(0, 2 * math.pi)
            inputs[0], inputs[1] = r * math.cos(a), r * math.sin(a)
            expect = "eccentricity"
        else:
            step = rng.choice([-1e-5, -rng.uniform(1e-9, 1.0), math.nan, -math.inf])
            expect = "step size"
        cases.append({"kind": "input", "inputs": inputs, "step": step, "expect": expect})
    return cases


def state_cases(rng: random.Random, n: int, variables: dict) -> list[dict]:
    """Serialized FMU states that are not ours: not JSON, not an object, injected or missing keys,
    values of the wrong type or out of range, another instance's n_balls; deserialized and set."""
    names = list(variables)
    reals = [k for k, v in variables.items() if v["type"] == "Real"]
    ints = [k for k, v in variables.items() if v["type"] == "Integer"]
    cases = []
    while len(cases) < n:
        pick = rng.randrange(10)
        if pick == 0:
            blob = {"raw": bytes(rng.randrange(256) for _ in range(rng.randrange(0, 64))).hex()}
        elif pick == 1:
            blob = {"json": rng.choice(["[1, 2]", "null", "3", '"state"', "[]", "{" * 5000 + "}" * 5000,
                                        "[" * 100000 + "]" * 100000, "1e999", "true"])}
        elif pick == 2:
            blob = {"mutate": "inject", "key": rng.choice(["__class__", "_bearing", "do_step", "vars", "x" * 9,
                                                           "_pending_error", "capacity", "__dict__"]),
                    "value": rng.choice([None, 1, "x", [1], {"a": 1}])}
        elif pick == 3:
            blob = {"mutate": "drop", "key": rng.choice(names)}
        elif pick == 4:
            blob = {"mutate": "set", "key": rng.choice(reals), "value": rng.choice(["text", None, [1.0], {}, True])}
        elif pick == 5:
            blob = {"mutate": "set", "key": rng.choice(ints), "value": rng.choice([7.9, "8", None, 1e300, True])}
        elif pick == 6:
            blob = {"mutate": "set", "key": "n_balls", "value": rng.choice([9, 7, 3, 20, 21, 0, -1, 10**9])}
        elif pick == 7:
            blob = {"mutate": "set", "key": rng.choice(reals), "value": rng.choice(["NaN", "Infinity", "-Infinity"])}
        elif pick == 8:
            blob = {"mutate": "set", "key": rng.choice(["youngs_modulus", "contact_stiffness", "ball_diameter",
                                                        "poisson_ratio", "radial_clearance"]),
                    "value": rng.choice([-1.0, 123.0, 1e300, -1e300])}
        else:
            blob = {"mutate": "set", "key": rng.choice(["loaded_balls", "damping_model"]),
                    "value": rng.choice([-1, 10**6, 3.5, "2"])}
        blob["kind"] = "state"
        cases.append(blob)
    return cases


def crank_state_cases(rng: random.Random, n: int) -> list[dict]:
    """SliderCrank states with a bad mechanism state, history or published outputs, or injected keys."""
    bad_rows = [None, 1, "x", [[1.0, 2.0]], [[math.nan] * 4], [["a"] * 4], [[0.0] * 4] * 3, [[1e308] * 3]]
    cases = []
    while len(cases) < n:
        pick = rng.randrange(6)
        if pick == 0:
            mutation = {"key": "_y", "value": rng.choice([None, [], [0.0], "y", [[0.0]], {"a": 1}, "nan", "long"])}
        elif pick == 1:
            mutation = {"key": "_history", "value": rng.choice(bad_rows + ["long", "nan"])}
        elif pick == 2:
            mutation = {"key": "_published", "value": rng.choice(bad_rows)}
        elif pick == 3:
            mutation = {"key": rng.choice(["_system", "_scheme", "_n", "__class__", "extra"]), "value": 1}
        elif pick == 4:
            mutation = {"key": rng.choice(["rpm", "crank_length", "max_substeps", "force_lag_steps"]),
                        "value": rng.choice([-1.0, 1e300, "1200", None, 7.5])}
        else:
            mutation = {"drop": rng.choice(["_y", "_history", "_published", "e_x", "rpm"])}
        cases.append({"kind": "crank_state", **mutation})
    return cases


SSP_MUTATIONS = ("absolute_source", "dotdot_source", "absolute_ssv", "dotdot_ssv", "drop_connection",
                 "garbage_ssd", "drop_member", "integer_ssv", "huge_ssv", "nan_ssv", "not_zip", "uri_source")


def ssp_cases(rng: random.Random, n: int) -> list[dict]:
    return [{"kind": "ssp", "mutation": rng.choice(SSP_MUTATIONS), "seed": rng.randrange(2**31)}
            for _ in range(n)]


CLI_BAD = [
    ("--step", ["inf", "-1", "0", "1e300", "nan", "1", "abc", "1e-12"]),
    ("--revs", ["0", "-2", "inf", "nan", "1e9"]),
    ("--rpm", ["-5", "0", "inf", "nan", "1e12"]),
    ("--output-interval", ["0", "-1e-5", "inf", "10"]),
    ("--balls", ["2", "0", "-1", "7.9", "100", "x"]),
    ("--rtol", ["0", "-1", "2"]),
    ("--set", ["n_balls=7.9", "damping_model=1.7", "contact_stiffness=1e300", "youngs_modulus=-1",
               "poisson_ratio=0.7", "nonexistent=1", "n_balls", "ball_diameter=x", "radial_clearance=inf",
               "allow_ball_overlap=2", "damping_model=3", "cage_angle_start=1e300"]),
    ("--scheme", ["nonsense"]),
    ("--joint", ["hinge"]),
    ("--fmu", ["/nonexistent/BallBearing.fmu"]),
    ("--ssp", ["/nonexistent.ssp", "/etc/passwd"]),
]


def cli_cases(rng: random.Random, n: int) -> list[dict]:
    cases = []
    while len(cases) < n:
        option, values = rng.choice(CLI_BAD)
        value = rng.choice(values)
        extra = rng.sample(["--no-plots", "--no-ideal", "--quiet"], rng.randrange(0, 3))
        if option == "--set":
            expect = [value.split("=")[0]]
        elif option in ("--fmu", "--ssp"):
            expect = [value]
        else:
            expect = [option[2:], option[2:].replace("-", "_"), value]
        cases.append({"kind": "cli", "argv": ["run", option, value, "--revs", "0.01", *extra]
                      if option != "--revs" else ["run", option, value, *extra], "expect": expect})
    return cases


def generate(seed: int, variables: dict) -> list[dict]:
    rng = random.Random(seed)
    cases = (parameter_cases(rng, COUNTS["parameter"], variables) + input_cases(rng, COUNTS["input"])
             + state_cases(rng, COUNTS["state"], variables) + crank_state_cases(rng, COUNTS["crank_state"])
             + ssp_cases(rng, COUNTS["ssp"])
             + cli_cases(rng, COUNTS["cli"]))
    for i, case in enumerate(cases):
        case["id"] = i
    return cases


# ----------------------------------------------------------------------------------- the worker
class Worker:
    """Runs cases in this process: one extracted BallBearing FMU, a fresh instance per FMU case."""

    def __init__(self, fmu: str, ssp: str, tmp: str):
        from fmpy import read_model_description
        from fmpy.fmi2 import FMU2Slave

        from mechanism.cosim.endpoints import shared_extraction
        self.fmu, self.ssp, self.tmp = Path(fmu), Path(ssp), Path(tmp)
        self.md = read_model_description(fmu)
        self.var = {v.name: v for v in self.md.modelVariables}
        self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=shared_extraction(self.fmu, self.md.guid),
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="fuzz")

    def instance(self):
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                               fmi2CallbackLoggerTYPE, calloc, free)
        messages = []

        def log(env, instance, status, category, message):
            messages.append(message.decode("utf-8", "replace"))
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(log)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._callbacks = callbacks
        self.slave.instantiate(callbacks=callbacks, loggingOn=True)
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        return messages

    def set(self, kind: str, vr: int, value) -> None:
        s = self.slave
        if kind == "Real":
            s.setReal([vr], [float(value)])
        elif kind == "Integer":
            s.setInteger([vr], [int(value)])
        else:
            s.setBoolean([vr], [bool(value)])

    def inputs(self, values) -> None:
        self.slave.setReal([self.var[n].valueReference for n in INPUTS], [float(x) for x in values])

    def free(self) -> None:
        # fmi2FreeInstance itself: fmpy's freeInstance() also unloads the library, which this one object
        # keeps using for the next instance
        for call in (self.slave.terminate, lambda: self.slave.fmi2FreeInstance(self.slave.component)):
            try:
                call()
            except Exception:
                pass

    def run(self, case: dict) -> tuple[bool, str]:
        return getattr(self, f"case_{case['kind']}")(case)

    # -- FMU cases: refused = an FMI status above warning on the call or the next doStep, plus a logger
    #    message naming the cause; the instance must still answer getReal afterwards
    def _refused(self, calls, messages, expect: str) -> tuple[bool, str]:
        from fmpy.fmi1 import FMICallException
        refused = False
        for call in calls:
            try:
                call()
            except FMICallException:
                refused = True
                break
        try:
            self.slave.getReal([self.var["F_x"].valueReference])
        except Exception as err:  # an FMU that cannot even answer a get after the error
            return False, f"getReal after the error failed: {err!r}"
        text = " | ".join(messages)
        if not refused:
            return False, f"accepted (no error status); messages: {text[:300]}"
        if expect.lower() not in text.lower():
            return False, f"refused, but no message names {expect!r}: {text[:300]}"
        return True, text[:200]

    def case_parameter(self, case):
        messages = self.instance()
        try:
            vr = case.get("vr", self.var[case["name"]].valueReference)
            return self._refused([lambda: self.set(case["as"], vr, case["value"]),
                                  self.slave.exitInitializationMode,
                                  lambda: self.slave.doStep(0.0, 1e-5)], messages, case["expect"])
        finally:
            self.free()

    def case_input(self, case):
        messages = self.instance()
        try:
            self.inputs(GOOD_INPUTS)
            self.slave.exitInitializationMode()
            self.slave.doStep(0.0, 1e-5)
            return self._refused([lambda: self.inputs(case["inputs"]),
                                  lambda: self.slave.doStep(1e-5, case["step"])], messages, case["expect"])
        finally:
            self.free()

    def case_crank_state(self, case):
        """A SliderCrank instance (extracted from the archive), initialised and stepped once, then a bad state."""
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        if not hasattr(self, "crank"):
            folder = self.tmp / f"crank_{os.getpid()}"
            with zipfile.ZipFile(self.ssp) as z:
                z.extract("resources/SliderCrank.fmu", folder)
            fmu = folder / "resources" / "SliderCrank.fmu"
            md = read_model_description(str(fmu))
            self.crank = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu), str(folder / "x")),
                                   modelIdentifier=md.coSimulation.modelIdentifier, instanceName="crank")
            self.crank_vr = {v.name: v.valueReference for v in md.modelVariables}
        slave, saved = self.slave, self.var
        self.slave, self.var = self.crank, None
        try:
            messages = self.instance()
            slave_vr = self.crank_vr
            self.slave.exitInitializationMode()
            self.slave.doStep(0.0, 1e-5)
            good = self.slave.getFMUstate()
            state = json.loads(bytes(self.slave.serializeFMUstate(good)).decode())
            self.slave.freeFMUState(good)
            if "drop" in case:
                state.pop(case["drop"])
            else:
                value = case["value"]
                if value == "long":
                    value = [[0.0] * len(state["_history"][0])] * 50 if case["key"] == "_history" else [0.0] * 99
                elif value == "nan":
                    value = [[math.nan] * len(row) for row in state["_history"]] if case["key"] == "_history" \
                        else [math.nan] * len(state["_y"])
                state[case["key"]] = value
            data = json.dumps(state).encode()
            probe = [slave_vr["e_x"], slave_vr["slider_x"]]
            before = self.slave.getReal(probe)

            def restore():
                bad = self.slave.deSerializeFMUstate(data)
                self.slave.setFMUState(bad)
                self.slave.freeFMUState(bad)
            from fmpy.fmi1 import FMICallException
            refused = False
            for call in (restore, lambda: self.slave.doStep(1e-5, 1e-5)):
                try:
                    call()
                except FMICallException:
                    refused = True
                    break
            after = self.slave.getReal(probe)
            text = " | ".join(messages)
            if not refused or "state" not in text.lower():
                return False, f"not refused with a message: {text[:300]}"
            if after != before:
                return False, f"the instance changed although the state was refused: {before} -> {after}"
            return True, text[:200]
        finally:
            self.free()
            self.slave, self.var = slave, saved

    def case_state(self, case):
        messages = self.instance()
        try:
            self.inputs(GOOD_INPUTS)
            self.slave.exitInitializationMode()
            self.slave.doStep(0.0, 1e-5)
            good = self.slave.getFMUstate()
            blob = self.slave.serializeFMUstate(good)
            self.slave.freeFMUState(good)
            if "raw" in case:
                data = bytes.fromhex(case["raw"])
            elif "json" in case:
                data = case["json"].encode()
            else:
                state = json.loads(bytes(blob).decode())
                key = case["key"]
                if case["mutate"] == "drop":
                    state.pop(key, None)
                else:
                    state[key] = case["value"]
                data = json.dumps(state).encode()
            before = self.slave.getReal([self.var["F_x"].valueReference, self.var["cage_angle"].valueReference])

            def restore():
                bad = self.slave.deSerializeFMUstate(bytes(data))
                self.slave.setFMUState(bad)
                self.slave.freeFMUState(bad)
            ok, detail = self._refused([restore, lambda: self.slave.doStep(1e-5, 1e-5)], messages, "state")
            after = self.slave.getReal([self.var["F_x"].valueReference, self.var["cage_angle"].valueReference])
            if ok and after != before:
                return False, f"the instance changed although the state was refused: {before} -> {after}"
            return ok, detail
        finally:
            self.free()

    # -- SSP archives: load_ssp must raise SspError naming the problem
    def case_ssp(self, case):
        from mechanism import ssp as sm
        rng = random.Random(case["seed"])
        path = self.tmp / f"fuzz_{case['id']}.ssp"
        expect = mutate_ssp(self.ssp, path, case["mutation"], rng)
        try:   # the default set, then each variant SSD (checked when it is chosen)
            with sm.load_ssp(path) as system:
                names = list(system.parameter_set_names)
            for name in names:
                with sm.load_ssp(path, name):
                    pass
            return False, "accepted"
        except sm.SspError as err:
            if expect.lower() not in str(err).lower():
                return False, f"SspError without {expect!r}: {err}"
            return True, str(err)[:200]
        finally:
            path.unlink(missing_ok=True)

    # -- command lines: exit status != 0 and one stderr line naming the value
    def case_cli(self, case):
        import contextlib
        import io

        from mechanism.cli import main
        err = io.StringIO()
        argv = case["argv"] + ["--out", str(self.tmp / f"cli_{case['id']}"), "--fmu", str(self.fmu)] \
            if "--fmu" not in case["argv"] and "--ssp" not in case["argv"] else \
            case["argv"] + ["--out", str(self.tmp / f"cli_{case['id']}")]
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                code = main(argv)
            except SystemExit as exit_:   # argparse
                code = exit_.code
        text = err.getvalue().strip()
        lines = [line for line in text.splitlines() if line.strip()]
        if code in (0, None):
            return False, f"exit 0 for {argv}"
        if "Traceback" in text:
            return False, f"traceback: {text[-300:]}"
        if not any(word.lower() in text.lower() for word in case["expect"]):
            return False, f"exit {code} but the message does not name {case['expect']!r}: {text[:300]}"
        if len(lines) > 2:   # argparse: usage + error; ours: one line
            return False, f"{len(lines)} lines on stderr: {text[:300]}"
        return True, lines[-1][:200]


def mutate_ssp(source: Path, target: Path, mutation: str, rng: random.Random) -> str:
    """Write a malformed copy of the archive ``source`` to ``target``; returns a word its error must name."""
    with zipfile.ZipFile(source) as z:
        members = {name: z.read(name) for name in z.namelist()}
    ssd = members["SystemStructure.ssd"].decode()
    ssvs = [n for n in members if n.endswith("bearing.ssv")]
    if mutation == "not_zip":
        target.write_bytes(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 4096))))
        return "zip"
    expect = ""
    if mutation in ("absolute_source", "dotdot_source", "uri_source"):
        new = {"absolute_source": rng.choice(["/etc/passwd", "/tmp/BallBearing.fmu", "//server/x.fmu"]),
               "dotdot_source": rng.choice(["../BallBearing.fmu", "resources/../../x.fmu", "a/../../../etc/passwd"]),
               "uri_source": rng.choice(["file:///etc/passwd", "http://example.com/x.fmu", "C:\\x.fmu"])}[mutation]
        ssd = ssd.replace('source="resources/BallBearing.fmu"', f'source="{new}"', 1)
        expect = "source"
    elif mutation in ("absolute_ssv", "dotdot_ssv"):
        old = ssvs[0]
        new = "/etc/passwd" if mutation == "absolute_ssv" else "../" * rng.randrange(1, 5) + "etc/passwd"
        ssd = ssd.replace(f'source="{old}"', f'source="{new}"', 1)
        expect = "source"
    elif mutation == "drop_connection":
        start = ssd.index("<ssd:Connection ")
        starts = [i for i in range(len(ssd)) if ssd.startswith("<ssd:Connection ", i)]
        start = rng.choice(starts)
        end = ssd.index("/>", start) + 2
        ssd = ssd[:start] + ssd[end:]
        expect = "unconnected"
    elif mutation == "garbage_ssd":
        cut = rng.randrange(1, len(ssd) - 1)
        ssd = ssd[:cut] + rng.choice(["<", "&", "\x00", "]]>", "<!ENTITY x SYSTEM 'file:///etc/passwd'>"]) + ssd[cut:]
        expect = "SystemStructure.ssd"
    elif mutation == "drop_member":
        name = rng.choice([n for n in members if n.startswith("resources/")])   # a variant .ssd is optional
        del members[name]
        expect = "missing"
    else:
        name = rng.choice(ssvs)
        text = members[name].decode()
        if mutation == "integer_ssv":
            param, value = rng.choice([("n_balls", "7.9"), ("damping_model", "1.7"), ("n_balls", "8.0")])
        elif mutation == "huge_ssv":
            param, value = rng.choice([("contact_stiffness", "1e300"), ("youngs_modulus", "1e300"),
                                       ("radial_clearance", "1e3"), ("cage_angle_start", "-1e300")])
        else:
            param, value = rng.choice([("contact_stiffness", "NaN"), ("ball_diameter", "INF"),
                                       ("damping_coefficient", "-INF")])
        import re
        text, count = re.subn(rf'(name="{param}"\s*>\s*<ssv:\w+ value=")[^"]*"', rf'\g<1>{value}"', text)
        assert count == 1, (param, name)
        members[name] = text.encode()
        expect = param
    members["SystemStructure.ssd"] = ssd.encode()
    with zipfile.ZipFile(target, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    return expect


def worker_main(fmu: str, ssp: str, tmp: str) -> int:
    """Read a JSON list of cases on stdin; print one JSON line per case as it finishes."""
    import warnings
    warnings.simplefilter("ignore")
    worker = Worker(fmu, ssp, tmp)
    for case in json.loads(sys.stdin.read()):
        try:
            ok, detail = worker.run(case)
        except Exception as err:   # the harness itself failed on this case: a failed case, not a crash
            ok, detail = False, f"harness: {type(err).__name__}: {str(err)[:300]}"
        print(json.dumps({"id": case["id"], "ok": ok, "detail": detail}), flush=True)
    return 0


# ----------------------------------------------------------------------------------- the driver
def run_batch(cases: list[dict], fmu: Path, ssp: Path, tmp: Path) -> tuple[dict[int, dict], str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, __file__, str(fmu), str(ssp), str(tmp)], input=json.dumps(cases),
                          capture_output=True, text=True, cwd=ROOT, env=env, timeout=900)
    results = {}
    for line in proc.stdout.splitlines():
        if line.startswith('{"id"'):
            r = json.loads(line)
            results[r["id"]] = r
    return results, f"exit {proc.returncode}: {proc.stderr.strip()[-300:]}"


def run_all(cases: list[dict], fmu: Path, ssp: Path, tmp: Path) -> tuple[dict[int, dict], list[str]]:
    """Batches in two processes at a time; the cases of a batch that died are rerun one per process."""
    batches = [cases[i:i + BATCH] for i in range(0, len(cases), BATCH)]
    results, crashes = {}, []
    with ThreadPoolExecutor(2) as pool:
        for batch, (found, status) in zip(batches, pool.map(lambda b: run_batch(b, fmu, ssp, tmp), batches)):
            results.update(found)
            missing = [c for c in batch if c["id"] not in found]
            for case in missing:   # the batch died: find the crasher
                alone, why = run_batch([case], fmu, ssp, tmp)
                if case["id"] in alone:
                    results.update(alone)
                else:
                    crashes.append(f"case {case['id']} {json.dumps(case)[:200]} crashed the host ({why})")
                    results[case["id"]] = {"id": case["id"], "ok": False, "detail": f"host crash ({why})"}
    return results, crashes


@pytest.fixture(scope="module")
def fuzz_inputs(ball_bearing_fmu, slider_crank_fmu, tmp_path_factory):
    from mechanism import ssp as sm
    tmp = tmp_path_factory.mktemp("fuzz")
    archive = sm.pack(tmp / "fuzz.ssp", {"BallBearing": ball_bearing_fmu, "SliderCrank": slider_crank_fmu})
    return ball_bearing_fmu, archive, tmp


def test_fuzz_every_malformed_case_is_refused_and_none_crashes(fuzz_inputs):
    from fmpy import read_model_description
    fmu, archive, tmp = fuzz_inputs
    md = read_model_description(str(fmu))
    variables = {v.name: {"type": v.type, "causality": v.causality} for v in md.modelVariables}
    cases = generate(SEED, variables)
    assert len(cases) >= 1000
    results, crashes = run_all(cases, fmu, archive, tmp)
    by_kind: dict[str, list[int]] = {}
    failed = []
    for case in cases:
        r = results.get(case["id"], {"ok": False, "detail": "no result"})
        by_kind.setdefault(case["kind"], [0, 0])[0 if r["ok"] else 1] += 1
        if not r["ok"]:
            failed.append(f"{case['kind']} #{case['id']} {json.dumps({k: v for k, v in case.items() if k != 'raw'})[:160]}"
                          f": {str(r['detail'])[:300]}")
    summary = ", ".join(f"{k}: {ok} refused/{ok + bad}" for k, (ok, bad) in by_kind.items())
    print(f"fuzz seed {SEED}: {len(cases)} cases, {len(crashes)} host crashes; {summary}")
    assert not crashes, "\n".join(crashes[:20])
    assert not failed, f"{len(failed)} cases not refused properly:\n" + "\n".join(failed[:30])


# ------------------------------------------------------------------------------------------ memory
#: issue 14's targets: (cycles, RSS growth limit [MB]) per phase of benchmarks/fmu_memory.py (about 10 s)
MEMORY_LIMITS = {"instantiate_free": (1000, 5.0), "load_unload": (200, 10.0)}
#: the same targets for the FMI 3.0 FMU (BallBearing3: FMU3Slave, Fmu3Endpoint; about 40 s)
MEMORY_LIMITS_FMI3 = {"instantiate_free3": (1000, 5.0), "load_unload3": (200, 10.0)}


def _assert_memory_growth(fmu: Path, limits: dict) -> None:
    """Run the phases of benchmarks/fmu_memory.py named in ``limits`` on ``fmu`` in one subprocess (the
    measured process is not pytest's, and a crash fails the test); assert each phase's RSS growth limit."""
    code = ("import json, runpy, sys; from pathlib import Path\n"
            "bench = runpy.run_path(sys.argv[1]); fmu = Path(sys.argv[2])\n"
            "print(json.dumps({name: bench[name](fmu, int(n)) for name, n in zip(sys.argv[3::2], sys.argv[4::2])}))")
    args = [str(ROOT / "benchmarks" / "fmu_memory.py"), str(fmu)]
    for name, (cycles, _) in limits.items():
        args += [name, str(cycles)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    measured = json.loads(proc.stdout.strip().splitlines()[-1])
    for name, (cycles, limit) in limits.items():
        before, after = measured[name]
        print(f"{name}: {cycles} cycles, RSS {before:.1f} -> {after:.1f} MB ({after - before:+.2f} MB)")
        assert after - before <= limit, f"{name}: {cycles} cycles grew the RSS by {after - before:.2f} MB > {limit} MB"


def test_memory_growth_of_a_long_lived_host(ball_bearing_fmu):
    """Issue 14's memory targets: 1,000 instantiate/free cycles of BallBearing.fmu in one process grow its
    resident memory by <= 5 MB, 200 FmuEndpoint load/unload cycles by <= 10 MB (each phase warms up first;
    before the slave shim each cycle kept ~590 kB, 580 MB in all). In a subprocess: the measured process
    is not pytest's, and a crash fails the test."""
    _assert_memory_growth(ball_bearing_fmu, MEMORY_LIMITS)


def test_memory_growth_of_a_long_lived_host_fmi3(tmp_path_factory):
    """The same targets for BallBearing3.fmu (FMI 3.0): 1,000 instantiate/free cycles (fmpy's FMU3Slave,
    fmi3FreeInstance) <= 5 MB, 200 Fmu3Endpoint load/unload cycles <= 10 MB. Before its slave shim
    (build_fmu.SHIM3) every instantiation after a last free imported the FMU's modules again: 1,000 cycles
    grew the RSS by about 19 MB (docs/robustness.md, Memory)."""
    from conftest import built_fmu
    _assert_memory_growth(built_fmu("BallBearing3", tmp_path_factory), MEMORY_LIMITS_FMI3)


if __name__ == "__main__":
    sys.exit(worker_main(*sys.argv[1:4]))
