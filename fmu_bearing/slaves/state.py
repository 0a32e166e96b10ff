"""Checking an FMU state completely before any of it is assigned (fmi2SetFMUstate, fmi2DeSerializeFMUstate).

pythonfmu 0.7 saves every registered variable in a dict (serialized as JSON) and, on restore, sets each
key: an unknown key becomes an attribute of the slave, a string lands in a Real and the host's next
fmi2GetReal fails, a state of an instance with other parameters half-restores it, and an exception (a
state that is not a dict) escapes into pythonfmu's C++ side and crashes the host (issue 14). The slaves
therefore call ``check_state`` first and assign nothing unless it returns None; the problem it returns
goes to the FMI logger (status error) and refuses the next doStep, and the instance stays as it was.

Standard library only (this module runs inside the FMU).
"""
import math

#: FMI 2.0 Integer range (fmi2Integer is a C int)
INT_MIN, INT_MAX = -2**31, 2**31 - 1


def variable_kinds(slave) -> dict:
    """{name: "Real" | "Integer" | "Boolean" | "String"} of the slave's registered variables ("Real" must be
    finite; a slave marks a Real that may be infinite, e.g. a life without load, as "Real or inf")."""
    from pythonfmu import Boolean, Integer, Real, String   # FMI 2.0 slaves only (the FMI 3.0 one has its own)
    kinds = {}
    for var in slave.vars.values():
        for cls, kind in ((Real, "Real"), (Integer, "Integer"), (Boolean, "Boolean"), (String, "String")):
            if isinstance(var, cls):
                kinds[var.name] = kind
                break
    return kinds


def _value_problem(name: str, kind: str, value):
    if kind in ("Real", "Real or inf"):
        if type(value) not in (int, float):
            return f"{name} = {value!r} is not a Real"
        if math.isnan(value) or kind == "Real" and not math.isfinite(value):
            return f"{name} = {value!r} is not finite"
    elif kind == "Integer":
        if type(value) is not int or not INT_MIN <= value <= INT_MAX:
            return f"{name} = {value!r} is not an Integer"
    elif kind == "Boolean":
        if type(value) is not bool:
            return f"{name} = {value!r} is not a Boolean"
    elif type(value) is not str:
        return f"{name} = {value!r} is not a String"
    return None


def check_state(state, kinds: dict, model: str, fixed: dict = None, extra=()):
    """The first problem of ``state`` as a state of this instance, or None if it can be assigned.

    ``kinds``: the registered variables (``variable_kinds``); their keys must all be present, of their
    type and finite ("Real or inf": not NaN). ``extra``: further keys the slave may save itself (allowed, not
    required; checked by the slave). ``fixed``:
    name -> current value of the variables that may not change (the parameters of an initialised
    instance, e.g. n_balls: a state of an instance with other parameters is not ours).
    """
    if not isinstance(state, dict):
        return f"not a {model} state (a JSON {type(state).__name__}, not an object)"
    allowed = set(kinds) | set(extra)
    unknown = sorted(str(k) for k in state if k not in allowed)
    if unknown:
        return f"not a {model} state of this build: unknown key {unknown[0]!r}"
    missing = [k for k in kinds if k not in state]
    if missing:
        return f"not a {model} state of this build: no value for {missing[0]!r} (another per-ball capacity?)"
    for name, kind in kinds.items():
        problem = _value_problem(name, kind, state[name])
        if problem is not None:
            return problem
    for name, value in (fixed or {}).items():
        if state[name] != value:
            return (f"a state of another instance: {name} = {state[name]!r}, this instance has {value!r} "
                    f"(parameters are fixed after initialisation)")
    return None


def finite_rows(value, width: int, most: int):
    """True if ``value`` is a list of at most ``most`` lists of ``width`` finite numbers."""
    return (isinstance(value, list) and len(value) <= most
            and all(isinstance(row, list) and len(row) == width
                    and all(type(x) in (int, float) and math.isfinite(x) for x in row) for row in value))
