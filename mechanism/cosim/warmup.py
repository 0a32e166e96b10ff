"""A first run's second process: compile what the run's process would compile after its own kernels into numba's
disk cache, while the run's process compiles the kernels it calls from Python first (issue 11: the first run's
compile, on two cores).

``compiled_driver.start_warmup`` starts ``python -m mechanism.cosim.warmup`` when ``run_steps`` is not cached. The
run's process compiles ``prepare``, ``max_violation`` and ``finish`` (and their callees) for ``CouplingLoop.start``
and the first sample, then the energy account's kernels (and ``kernels.advance`` when its step calls it,
``RUN_SHARE``); this process compiles, stage by stage (``STAGES``), the loop's own functions, the scheme's (force
models or law-model's step) and the component's exchange, printing each stage's name when it is done. The
run waits (``compiled_driver.finish_warmup``) only for the stages its step needs (``needed``: an FMU run's step has
no in-process law, only law-model's has law-model's functions, only the other schemes' their force models), and
its compile of ``run_steps`` loads these functions from the cache instead of compiling them. This process is ended
then, unless it has the stages the run calls later still to compile (``later``: a law-model run's ideal
counterpart's ``kernels.advance``), which it compiles while the run compiles ``run_steps``
(``compiled_driver.await_later`` waits for them before the run that calls them).

Each function is compiled for the argument types its caller gives it (``run_steps``, or the run's Python calls
for the energy account); tests/test_compile_time.py holds them against the run's: a different type would only mean
a second specialisation compiled by the run, never a different number. Nothing is executed here.
"""
from __future__ import annotations

import sys

from numba import types

from mechanism.cosim import compiled_loop as cl
from mechanism.cosim import component_call as cc
from mechanism.cosim import law_model_kernel as lmk
from mechanism.cosim.energy_kernel import stage_integrals
from mechanism.cosim.law_kernel import elastic_energy, evaluate
from mechanism.multibody import kernels

_F, _I, _B, _N = types.float64, types.int64, types.boolean, types.none
_F1, _F2 = types.float64[::1], types.float64[:, ::1]
_I1, _U1 = types.int64[::1], types.uint32[::1]

#: the energy account's kernels as the run's process calls them from Python (``EnergyAccount``), before its first chunk
ENERGY = (
    (evaluate, (_F1, _F, _F, _F, _F, _F, _F, _F, _F1, _F1)),
    (elastic_energy, (_F1, _F, _F, _F)),
    (stage_integrals, (_F1, _F2, _I, _F, _F)),
)
#: (function, argument types) as ``run_steps`` calls them, for every component and scheme; their callees (the life
#: sums, the FMU's state calls) compile with them
LOOP = (
    (cl._release, (_I, _I1, _I, _I1)),
    (cc.save, (_I, _F1, _F1, _I1)),
    (cc.restore, (_I, _F1, _F1, _I1, _I)),
    (cc.sample, (_I, _F1, _I1, _U1, _U1, _U1, _F1)),
    (cl.substeps, (_F, _F1, _F, _F, _I)),
    (cl._push, (_F2, _I, _F1, _I)),
    (cl.converged, (_F1, _F1, _F, _F)),
    (cl.onset_jumps, (_F1, _F1, _F, _F1, _F, _F2)),
    (cl.same_jumps, (_F2, _I, _F2, _I, types.Omitted(1e-3))),
    (cl._fail, (_F1, _I, _I, _F, _F, _F, _F, _F, _F, _F)),
    (cl._copy, (_F1, _F1, _I)),
    (cl._copy_rows, (_F2, _F2, _I)),
)
#: the force models of every scheme but law-model (``run_steps``' FM not None) and their pass checks
FORCE_MODEL = (
    (cl.hold_model, (_I, _F2, _I, _F1)),
    (cl.trial_model, (_F1, _F1, _F2, _I, _F1)),
    (cl.drift_model, (_F2, _I, _B, _F1)),
    (cl.k1_valid, (_F1, _F, _F1, _F1)),
    (cl.next_pass_negligible, (_F1, _F1, _F, _F, _F)),
)
#: the RK4 step (``kernels.advance``, with the energy account's arrays) as ``run_steps`` calls it
ADVANCE = ((kernels.advance, (_F1, _F, _F, _I, _F, _F1, _F1, _B, _I1, _F1, _I1, _F1, _F1, _F1, _F1, _F1, _F2)),)
#: the exchange with an FMU (``P`` None: ``fmu_native`` only) and with the in-process law
_EXCHANGE = (_I, _F1, _F, _F1, _I1, _U1, _U1, _F, _F, _F1, _F1, _I, _F, _F1, _I1)
FMU = ((cl._exchange, (_I, _N, *_EXCHANGE[2:])),)
IN_PROCESS = ((cl._exchange, _EXCHANGE),)
#: law-model's step (law_model_kernel; its RK4 compiles the multibody stage kernels with it)
LAW_MODEL = (
    (cl.mismatch_negligible, (_F, _F, _F1, _F, _F, _F)),
    (lmk.set_cage, (_F1, _F1, _F, _F, _F)),
    (lmk.begin, (_F1, _F1, _F1, _F1, _F1, _F1, _B, _F)),
    (lmk.substep_tangent, (_F1, _F1, _F1)),
    (lmk.onset_fraction, (_F, _F, _F, _F)),
    (lmk.onset_weights, (_F, _F, _F)),
    (lmk.onset_corrections, (_F1, _F1, _I, _F2, _F1, _F2)),
    (lmk.at_least, (_F1, _I, _I)),
    (lmk.end_mismatch, (_F1, _F1, _F1, _F1, _F1)),
    (lmk.any_onset, (_F1, _F1, _I, _F2, _F1, _F2)),
    (lmk.advance, (_F1, _F, _F, _I, _F, _F1, _F1, _F1, _F1, _F2, _F2, _I1, _F1, _I1, _F1, _F1, _F1, _F1, _F2)),
)
#: the stages in the order compiled: (name, functions). The energy account's kernels come last: the run's process
#: compiles them itself after ``finish`` (about when this process is done with the step's stages), so a first run
#: does not wait for them; they are here for a warm-up run by itself (``python -m mechanism.cosim.warmup``)
STAGES = (("loop", LOOP), ("force-model", FORCE_MODEL), ("advance", ADVANCE), ("fmu", FMU), ("in-process", IN_PROCESS),
          ("law-model", LAW_MODEL), ("energy", ENERGY))
#: the functions every run's step calls (the rest: ``needed``)
SIGNATURES = tuple(sig for _, stage in STAGES for sig in stage)


def needed(fmu: bool, law_model: bool) -> list[str]:
    """The stages the step of a run needs (``run_steps``): through an FMU or in-process, law-model's step or another
    scheme's force models with ``kernels.advance``."""
    return ["loop", "fmu" if fmu else "in-process"] + (["law-model"] if law_model else ["force-model", "advance"])


def later(fmu: bool, law_model: bool) -> list[str]:
    """The stages a run calls after its step, from Python, that its step does not need: ``kernels.advance`` for a
    law-model run (the ideal counterpart's Python loop). This process compiles them after ``needed``'s while the
    run's process compiles ``run_steps``; the run does not wait for them (``compiled_driver.await_later``)."""
    return ["advance"] if law_model else []


#: the stages the run's process compiles itself when its step needs them, after its own kernels and before it waits
#: for this process (the two cores of a first run balanced; ``kernels.advance``'s callees are in its cache already
#: from ``finish``). docs/kernels.md, "The first run's compile"
RUN_SHARE = ("advance",)


def compile_stages(names, done=None) -> None:
    """Compile (or load from the cache) the stages ``names`` in their order (``start_warmup`` puts ``later``'s last);
    ``done(name)`` after each."""
    stages = dict(STAGES)
    for name in names:
        for function, args in stages[name]:
            function.compile(args)
        if done is not None:
            done(name)


def main(names: list[str] | None = None) -> int:
    """Compile (or load from the cache) the stages ``names`` in their order (default: all, in ``STAGES``' order),
    printing each stage's name when it is in the cache. An unknown name: one line naming it and the stages on
    standard error, status 2, nothing compiled."""
    known = [name for name, _ in STAGES]
    unknown = [name for name in names or () if name not in known]
    if unknown:
        print(f"error: no warm-up stage {unknown[0]!r} (the stages: {', '.join(known)})", file=sys.stderr)
        return 2
    compile_stages(known if names is None else names, lambda name: print(name, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:] or None))
