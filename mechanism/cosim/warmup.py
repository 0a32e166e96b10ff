"""A first run's second process: compile the compiled loop's own functions into numba's disk cache while the
run's process compiles the multibody kernels (issue 11: the first run's compile, on two cores).

``compiled_driver.start_warmup`` starts ``python -m mechanism.cosim.warmup`` when ``run_steps`` is not cached;
the run waits for it before its first chunk, whose compile of ``run_steps`` then loads these functions from the
cache instead of compiling them. Each is compiled for the argument types ``run_steps`` calls it with
(``SIGNATURES``; tests/test_compile_time.py holds them against the run's): a different type would only mean a
second specialisation compiled by the run, never a different number. Nothing is executed here.
"""
from __future__ import annotations

from numba import types

from mechanism.cosim import compiled_loop as cl
from mechanism.cosim import component_call as cc
from mechanism.cosim import law_model_kernel as lmk
from mechanism.cosim.energy_kernel import stage_integrals
from mechanism.cosim.law_kernel import elastic_energy

_F, _I, _B = types.float64, types.int64, types.boolean
_F1, _F2 = types.float64[::1], types.float64[:, ::1]
_I1, _U1 = types.int64[::1], types.uint32[::1]

#: (function, argument types) as ``run_steps`` calls them; their callees (the law, the life sums, the FMU's
#: calls, the scheme's helpers) compile with them
SIGNATURES = (
    (cl._exchange, (_I, _F1, _F, _F1, _I1, _U1, _U1, _F, _F, _F1, _F1, _I, _F, _F1, _I1)),
    (cl._release, (_I, _I1, _I, _I1)),
    (cc.save, (_I, _F1, _F1, _I1)),
    (cc.restore, (_I, _F1, _F1, _I1, _I)),
    (cc.sample, (_I, _F1, _I1, _U1, _U1, _U1, _F1)),
    (cl.hold_model, (_I, _F2, _I, _F1)),
    (cl.trial_model, (_F1, _F1, _F2, _I, _F1)),
    (cl.drift_model, (_F2, _I, _B, _F1)),
    (cl.substeps, (_F, _F1, _F, _F, _I)),
    (cl.k1_valid, (_F1, _F, _F1, _F1)),
    (cl._push, (_F2, _I, _F1, _I)),
    (cl.converged, (_F1, _F1, _F, _F)),
    (cl.onset_jumps, (_F1, _F1, _F, _F1, _F, _F2)),
    (cl.same_jumps, (_F2, _I, _F2, _I, types.Omitted(1e-3))),
    (cl.next_pass_negligible, (_F1, _F1, _F, _F, _F)),
    (cl.mismatch_negligible, (_F, _F, _F1, _F, _F, _F)),
    (cl._fail, (_F1, _I, _I, _F, _F, _F, _F, _F, _F, _F)),
    (cl._copy, (_F1, _F1, _I)),
    (cl._copy_rows, (_F2, _F2, _I)),
    # law-model's step (law_model_kernel; its RK4 compiles the multibody stage kernels with it)
    (lmk.set_cage, (_F1, _F1, _F, _F, _F)),
    (lmk.begin, (_F1, _F1, _F1, _F1, _F1, _F1, _B, _F)),
    (lmk.substep_tangent, (_F1, _F1, _F1)),
    (lmk.onset_fraction, (_F, _F, _F, _F)),
    (lmk.onset_weights, (_F, _F, _F)),
    (lmk.onset_corrections, (_F1, _F1, _I, _F2, _F1, _F2)),
    (lmk.at_least, (_F1, _I, _I)),
    (lmk.end_mismatch, (_F1, _F1, _F1, _F1, _F1)),
    (lmk.any_onset, (_F1, _F1, _I, _F2, _F1, _F2)),
    (lmk.advance, (_F1, _F, _F, _I, _F, _F1, _F1, _F1, _F1, _F2, _F2, _I1, _F1, _I1, _F1, _F1, _F1, _F1, _F1, _F2)),
)
#: called by the run's process itself before its first chunk (the energy account's set-up): not here
RUN_COMPILES = ((stage_integrals, (_F1, _F2, _I, _F, _F)), (elastic_energy, (_F1, _F, _F, _F)))


def main() -> None:
    """Compile (or load from the cache) every function of ``SIGNATURES``."""
    for function, args in SIGNATURES:
        function.compile(args)


if __name__ == "__main__":
    main()
