"""The bearing component's calls from the compiled loop (``compiled_loop.run_steps``), for either component.

``kind`` picks the component, so that one loop (and one compiled specialisation) serves both:

* ``IN_PROCESS``: the force law in-process, ``component_kernel.law_exchange`` on the state array ``cs``; its
  get/set FMU state is a copy of ``cs`` (into ``snap``);
* ``FMU``: an FMI 2.0 FMU (``FmuEndpoint``) called natively through ``fmu_native``: set the 6 inputs, doStep,
  get the coupling outputs; fmi2Get/Set/FreeFMUstate for the rollback; the sampled outputs by ``sample_into``.

Every call returns an fmi2Status (0 OK, 1 warning, above 1 a refusal; negative: ``fmu_native``'s own, nothing
called). The law's rejected inputs (non-finite, |e| beyond the limit) come back as ``ERROR``, nothing changed;
the caller words every refusal as the Python loop does (``compiled_driver``).
"""
from __future__ import annotations

from numba import njit

from mechanism.cosim import fmu_native
from mechanism.cosim.component_kernel import CS_CAGE, CS_LOADS, CS_OUT, law_exchange
from mechanism.multibody.kernels import KERNEL

#: the components (``kind``)
IN_PROCESS, FMU = 0, 1
#: fmi2Error: the status of the law's rejected inputs
ERROR = 3
#: coupling outputs of an exchange (``Exchanged``'s F_x .. c_yy): an FMU with fewer leaves the rest 0
N_COUPLING = 8


@njit(**KERNEL)
def exchange(kind, P, eccentricity_limit, cs, H, vr_in, vr_out, t0, h, sent, out) -> int:
    """One exchange over [t0, t0 + h] with the inputs ``sent`` held; the coupling outputs into ``out`` (8)."""
    if kind == IN_PROCESS:
        if law_exchange(P, eccentricity_limit, cs, h, sent) != 0:
            return ERROR
        for k in range(N_COUPLING):
            out[k] = cs[CS_OUT + k]
        return 0
    return fmu_native.exchange(H, vr_in, sent, t0, h, vr_out, out)


@njit(**KERNEL)
def save(kind, cs, snap, H):
    """Save the component's state: (status, the FMU state's pointer; 0 in-process: the copy is in ``snap``)."""
    if kind == IN_PROCESS:
        for i in range(cs.shape[0]):   # a loop, not a slice assignment (compile time, compiled_loop._copy)
            snap[i] = cs[i]
        return 0, 0
    status, state = fmu_native.get_state(H)
    return status, state


@njit(**KERNEL)
def restore(kind, cs, snap, H, state) -> int:
    """Roll the component back to the state ``save`` made (it stays valid for another restore)."""
    if kind == IN_PROCESS:
        for i in range(cs.shape[0]):
            cs[i] = snap[i]
        return 0
    return fmu_native.set_state(H, state)


@njit(**KERNEL)
def free(kind, H, state) -> int:
    """Free the state ``save`` made (nothing to free in-process)."""
    if kind == IN_PROCESS:
        return 0
    return fmu_native.free_state(H, state)


@njit(**KERNEL)
def sample(kind, cs, H, vr_real, vr_int, vr_bool, buf) -> int:
    """The component's sampled outputs after the last exchange into ``buf``, in its ``sample_names``' order
    (in-process: cage angle, loaded balls, max ball load, ball loads, as ``InProcessEndpoint.sample``)."""
    if kind == IN_PROCESS:
        buf[0] = cs[CS_CAGE]
        buf[1] = cs[CS_OUT + 8]
        buf[2] = cs[CS_OUT + 9]
        for r in range(buf.shape[0] - 3):
            buf[3 + r] = cs[CS_LOADS + r]
        return 0
    return fmu_native.sample_into(H, vr_real, vr_int, vr_bool, buf)
