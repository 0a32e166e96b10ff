"""The SSP reader: an .ssp archive (or an .ssd in an unpacked folder) into dataclasses, checked before any run.

Checked: the SSP 1.0 schema (the XSDs fmpy ships), the FMU resources, every connector against its FMU's
variable (causality, type, unit), every connection (known connectors, output to input, same type and
unit), every parameter of every set (known to the FMU, type, unit, the FMU's min/max, and the
component's own validation). Every problem is an ``SspError`` naming the file, the element and the
problem.
"""
from __future__ import annotations

import math
import os
import shutil
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from xml.etree import ElementTree as ET


from mechanism.ssp.system import (_q, FMU_TYPE, NS, SOURCE_SSD, SSD_IN_ARCHIVE, SSD_SUFFIX, SspError,
                                  variant_ssd_name)


@dataclass(frozen=True)
class FmuVariable:
    """A variable of a component's FMU (from its modelDescription.xml)."""

    name: str
    causality: str
    type: str
    unit: str | None
    min: float | None
    max: float | None
    start: object


@dataclass(frozen=True)
class Connector:
    component: str
    name: str
    kind: str
    type: str | None
    unit: str | None


@dataclass(frozen=True)
class Connection:
    start_element: str
    start_connector: str
    end_element: str
    end_connector: str


@dataclass
class Component:
    """A component: its FMU (extracted path), model name, connectors, variables and parameter sets."""

    name: str
    source: str
    fmu: Path
    model_name: str
    connectors: dict[str, Connector]
    variables: dict[str, FmuVariable]
    parameter_sets: dict[str, dict[str, object]]     # set name -> {parameter: value}, in binding order
    parameter_files: dict[str, str]                  # set name -> .ssv path relative to the SSD
    values: dict[str, object] = field(default_factory=dict)  # every binding applied in order (SSP 1.0)


@dataclass
class SspSystem:
    """A checked SSP: components, connections and the parameter set of the SSD read (the default SSD or a
    variant). ``parameter_set_names``: that set first, then the archive's other sets. Close it (or use
    ``with``) to remove the folder an archive was unpacked into."""

    file: Path
    name: str
    components: dict[str, Component]
    connections: list[Connection]
    parameter_set_names: list[str]
    step_size: float | None
    stop_time: float | None
    workdir: Path | None = None
    ssd: str = SSD_IN_ARCHIVE           # the SSD read, relative to the archive (or its folder)

    def component_of_model(self, model_name: str) -> Component:
        for c in self.components.values():
            if c.model_name == model_name:
                return c
        raise SspError(self.file, "Elements", f"no component is an FMU of model {model_name!r} "
                                              f"(components: {', '.join(f'{c.name} ({c.model_name})' for c in self.components.values())})")

    def parameters(self, set_name: str | None = None) -> dict[str, dict[str, object]]:
        """component -> {parameter: value}: every binding of the SSD read applied in order (SSP 1.0).
        ``set_name``, if given, must be the set of that SSD (``check_parameter_set``)."""
        self.check_parameter_set(set_name)
        return {c.name: dict(c.values) for c in self.components.values()}

    def check_parameter_set(self, set_name: str | None) -> str:
        """The name of the SSD's parameter set (``set_name`` or None); an SspError naming the sets otherwise."""
        if not self.parameter_set_names:
            raise SspError(self.file, "ParameterBindings", "the system binds no parameter set")
        active = self.parameter_set_names[0]
        if set_name is None or set_name == active:
            return active
        if set_name in self.parameter_set_names:
            raise SspError(self.file, self.ssd, f"binds parameter set {active!r}, not {set_name!r}: "
                                                f"read the variant with load_ssp(path, {set_name!r})")
        raise SspError(self.file, "ParameterBindings", f"no parameter set named {set_name!r} "
                                                       f"(sets: {', '.join(self.parameter_set_names)})")

    def close(self) -> None:
        if self.workdir is not None:
            shutil.rmtree(self.workdir, ignore_errors=True)
            self.workdir = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _schema_dir() -> Path:
    import fmpy.ssp
    return Path(fmpy.ssp.__file__).resolve().parent / "schema"


def validate_schema(path: Path, schema: str, shown: str | Path | None = None) -> None:
    """Validate an XML file against one of the SSP 1.0 schemas fmpy ships (SystemStructureDescription.xsd,
    SystemStructureParameterValues.xsd); SspError with the first violations."""
    from lxml import etree
    shown = shown or path
    try:
        doc = etree.parse(str(path))
    except etree.XMLSyntaxError as err:
        raise SspError(shown, "XML", f"not well-formed: {err}") from None
    xsd = etree.XMLSchema(file=str(_schema_dir() / schema))
    if not xsd.validate(doc):
        # name the element a violation lies in (Parameter 'n_balls', Component 'bearing', ...)
        named = [(el.sourceline, f"{etree.QName(el).localname} {el.get('name')!r}")
                 for el in doc.iter() if isinstance(el.tag, str) and el.get("name") is not None]

        def where(line):
            inside = [label for start, label in named if start is not None and start <= line]
            return f" ({inside[-1]})" if inside else ""
        problems = "; ".join(f"line {e.line}{where(e.line)}: {e.message}" for e in list(xsd.error_log)[:3])
        raise SspError(shown, f"schema {schema}", f"does not validate: {problems}")


def _children(node: ET.Element, path: str) -> list[ET.Element]:
    return node.findall(path, {k: v for k, v in NS.items()})


def _type_of(node: ET.Element) -> tuple[str | None, ET.Element | None]:
    for kind in ("Real", "Integer", "Boolean", "String", "Enumeration", "Binary"):
        for prefix in ("ssc", "ssv"):
            child = node.find(_q(prefix, kind))
            if child is not None:
                return kind, child
    return None, None


def _read_fmu(file: Path, shown_file, component: str, fmu: Path) -> tuple[str, dict[str, FmuVariable]]:
    from fmpy import read_model_description
    try:
        md = read_model_description(str(fmu), validate=False)
    except Exception as err:
        raise SspError(shown_file, f"Component '{component}'", f"{fmu.name} is not a readable FMU: {err}") from None
    if md.coSimulation is None:
        raise SspError(shown_file, f"Component '{component}'", f"{fmu.name} does not support co-simulation")
    variables = {}
    for v in md.modelVariables:
        unit = v.unit if v.unit is not None else (v.declaredType.unit if v.declaredType is not None else None)
        variables[v.name] = FmuVariable(v.name, v.causality, v.type, unit,
                                        None if v.min in (None, "") else float(v.min),
                                        None if v.max in (None, "") else float(v.max), v.start)
    return md.modelName, variables


def _parse_value(kind: str, text: str | None):
    if text is None:
        raise ValueError("no value attribute")
    if kind == "Real":
        return float(text)
    if kind == "Integer":
        return int(text)
    if kind == "Boolean":
        low = text.strip().lower()
        if low not in ("true", "false", "1", "0"):
            raise ValueError(f"{text!r} is not a Boolean")
        return low in ("true", "1")
    return text


def _read_ssv(shown: str, path: Path, component: Component) -> tuple[str, dict[str, object]]:
    """(set name, {parameter: value}) of one .ssv, each parameter checked against the component's FMU."""
    validate_schema(path, "SystemStructureParameterValues.xsd", shown)
    root = ET.parse(path).getroot()
    set_name = root.get("name")
    values = {}
    for p in _children(root, "ssv:Parameters/ssv:Parameter"):
        name = p.get("name")
        element = f"Parameter '{name}'"
        kind, node = _type_of(p)
        var = component.variables.get(name)
        if var is None or var.causality not in ("parameter", "input"):
            known = ", ".join(n for n, v in component.variables.items() if v.causality == "parameter")
            what = "is not a variable" if var is None else f"is an {var.causality}, not a parameter"
            raise SspError(shown, element, f"parameter not in the FMU: {name!r} {what} of "
                                           f"{component.model_name} (its parameters: {known})")
        if kind != var.type:
            raise SspError(shown, element, f"type {kind} does not match the FMU's {var.type} variable")
        try:
            value = _parse_value(kind, node.get("value"))
        except ValueError as err:
            raise SspError(shown, element, f"invalid value: {err}") from None
        unit = node.get("unit")
        if unit is not None and var.unit is not None and unit != var.unit:
            raise SspError(shown, element, f"unit mismatch: [{unit}] here, [{var.unit}] in the FMU")
        if kind in ("Real", "Integer"):
            if not math.isfinite(value):
                raise SspError(shown, element, f"value {value!r} out of range: must be finite")
            if var.min is not None and value < var.min:
                raise SspError(shown, element, f"value {value!r} out of range: below the FMU's min {var.min:g}")
            if var.max is not None and value > var.max:
                raise SspError(shown, element, f"value {value!r} out of range: above the FMU's max {var.max:g}")
        values[name] = value
    return set_name, values


def check_component_parameters(shown: str, component: Component, values: dict) -> None:
    """The component's own validation of a parameter set (beyond the FMU's min/max): the bearing's
    ``validate`` (geometry, ball fit, ...) and the slider-crank's positive quantities."""
    if component.model_name == "BallBearing":
        from fmu_bearing.parameters import BearingParameterError, validate
        from fmu_bearing.parameters import from_values as bearing_parameters
        capacity = component.variables.get("n_balls")
        try:
            validate(bearing_parameters(values), capacity=None if capacity is None or capacity.max is None
                     else int(capacity.max))
        except BearingParameterError as err:
            raise SspError(shown, f"Parameter '{err.name}'", f"value {err.value!r} out of range: {err.reason}") from None
    elif component.model_name == "SliderCrank":
        from mechanism.ssp.slaves.slider_crank_fmu import POSITIVE
        for name in POSITIVE:
            if name in values and not values[name] > 0.0:
                raise SspError(shown, f"Parameter '{name}'", f"value {values[name]!r} out of range: must be positive")


def resolve_inside(base: Path, reference: str | None, shown, element: str, what: str) -> Path:
    """``reference`` (a component's or a ParameterBinding's ``source``) as a path inside ``base`` (the
    unpacked archive, or the folder of an .ssd): absolute paths, URIs and ``..`` are refused, so an SSP
    can never make us open a file outside itself."""
    if not reference:
        raise SspError(shown, element, f"no {what} source")
    rel = PurePosixPath(reference.replace("\\", "/"))
    if rel.is_absolute() or ":" in reference or ".." in rel.parts:
        raise SspError(shown, element, f"{what} source {reference!r} must be a relative path inside the "
                                       f"SSP (absolute paths, URIs and '..' are refused)")
    target = (base / rel).resolve()
    root = base.resolve()
    if root not in target.parents:
        raise SspError(shown, element, f"{what} source {reference!r} resolves outside the SSP ({target})")
    return target


def load_ssp(path: str | Path, parameter_set: str | None = None) -> SspSystem:
    """Read and check an .ssp archive (or an .ssd whose resources lie beside it) before any simulation.

    ``parameter_set``: None or the default set reads the default SSD (``SystemStructure.ssd``, or the .ssd
    given); another name reads the variant ``<name>.ssd`` beside it. Raises SspError naming the file, the
    element and the problem (an unknown set: the sets there are).
    """
    path = Path(path)
    if not path.exists():
        raise SspError(path, "file", "not found")
    workdir = None
    if path.suffix.lower() == SSD_SUFFIX:
        ssd, base, shown = path, path.parent, lambda rel: path.parent / rel
    else:
        if not zipfile.is_zipfile(path):
            raise SspError(path, "archive", "not an SSP archive (not a zip file)")
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
            if SSD_IN_ARCHIVE not in names:
                raise SspError(path, SSD_IN_ARCHIVE, "missing from the archive (an SSP's default SSD)")
            workdir = Path(tempfile.mkdtemp(prefix="ssp_"))
            for name in names:
                target = (workdir / name).resolve()
                if not str(target).startswith(str(workdir.resolve()) + os.sep) and target != workdir.resolve():
                    shutil.rmtree(workdir, ignore_errors=True)
                    raise SspError(path, name, "archive member outside the archive folder")
            z.extractall(workdir)
        ssd, base = workdir / SSD_IN_ARCHIVE, workdir
        shown = lambda rel: f"{path}!/{PurePosixPath(rel)}"  # noqa: E731
    if parameter_set is not None:
        variant = base / variant_ssd_name(parameter_set)
        if variant.is_file() and variant.resolve() != ssd.resolve():
            ssd = variant
    try:
        return _load(path, ssd, base, shown, workdir, parameter_set)
    except BaseException:
        if workdir is not None:
            shutil.rmtree(workdir, ignore_errors=True)
        raise


def _load(path, ssd, base, shown, workdir, parameter_set) -> SspSystem:
    ssd_shown = shown(ssd.relative_to(base).as_posix())
    validate_schema(ssd, "SystemStructureDescription.xsd", ssd_shown)
    root = ET.parse(ssd).getroot()
    if root.get("version") != "1.0":
        raise SspError(ssd_shown, "SystemStructureDescription", f"version {root.get('version')!r}: only SSP 1.0 is supported")
    system = root.find(_q("ssd", "System"))
    components: dict[str, Component] = {}
    for node in _children(system, "ssd:Elements/ssd:Component"):
        name, source = node.get("name"), node.get("source")
        element = f"Component '{name}'"
        if node.get("type", FMU_TYPE) != FMU_TYPE:
            raise SspError(ssd_shown, element, f"type {node.get('type')!r} is not supported (FMUs only)")
        fmu = resolve_inside(base, source, ssd_shown, element, "FMU")
        if not fmu.is_file():
            raise SspError(ssd_shown, element, f"missing FMU resource: {source} is not in the "
                                               f"{'archive' if workdir else 'folder'} (build the FMUs and pack: "
                                               f"`python -m mechanism ssp-pack`)")
        model_name, variables = _read_fmu(path, ssd_shown, name, fmu)
        comp = Component(name, source, fmu, model_name, {}, variables, {}, {})
        for c in _children(node, "ssd:Connectors/ssd:Connector"):
            cname, kind = c.get("name"), c.get("kind")
            vtype, tnode = _type_of(c)
            unit = tnode.get("unit") if tnode is not None else None
            celement = f"Connector '{name}.{cname}'"
            var = variables.get(cname)
            if var is None:
                raise SspError(ssd_shown, celement, f"unknown connector: {model_name} has no variable {cname!r}")
            if kind in ("input", "output") and var.causality != kind:
                raise SspError(ssd_shown, celement, f"kind {kind!r} but the FMU's variable is an {var.causality}")
            if vtype is not None and vtype != var.type:
                raise SspError(ssd_shown, celement, f"type {vtype} but the FMU's variable is {var.type}")
            if (unit or None) != (var.unit or None):
                raise SspError(ssd_shown, celement, f"unit mismatch: [{unit}] here, [{var.unit}] in {model_name}")
            comp.connectors[cname] = Connector(name, cname, kind, vtype or var.type, unit)
        components[name] = comp
        for b in _children(node, "ssd:ParameterBindings/ssd:ParameterBinding"):
            src = b.get("source")
            belement = f"ParameterBinding of component '{name}'"
            if src is None:
                raise SspError(ssd_shown, belement, "inline ParameterValues are not supported: use a .ssv source")
            if b.get("prefix"):
                raise SspError(ssd_shown, belement, "a prefix is not supported")
            ssv = resolve_inside(base, src, ssd_shown, belement, "parameter file")
            if not ssv.is_file():
                raise SspError(ssd_shown, belement, f"missing parameter file {src}")
            set_name, values = _read_ssv(str(shown(src)), ssv, comp)
            if set_name in comp.parameter_sets:
                raise SspError(shown(src), "ParameterSet", f"a second set named {set_name!r} bound to {name!r}")
            check_component_parameters(str(shown(src)), comp, values)
            comp.parameter_sets[set_name] = values
            comp.parameter_files[set_name] = src
            comp.values.update(values)   # SSP 1.0: every binding is applied, in order
    connections = []
    inputs_connected: dict[tuple[str, str], Connection] = {}
    for c in _children(system, "ssd:Connections/ssd:Connection"):
        con = Connection(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
        element = (f"Connection {con.start_element}.{con.start_connector} -> "
                   f"{con.end_element}.{con.end_connector}")
        if con.start_element is None or con.end_element is None:
            raise SspError(ssd_shown, element, "connections to the system's own connectors are not supported")
        ends = []
        for elem, cname, role in ((con.start_element, con.start_connector, "start"),
                                  (con.end_element, con.end_connector, "end")):
            comp = components.get(elem)
            if comp is None:
                raise SspError(ssd_shown, element, f"unknown {role} element {elem!r}")
            connector = comp.connectors.get(cname)
            if connector is None:
                raise SspError(ssd_shown, element, f"unknown connector: {elem!r} declares no connector {cname!r}")
            ends.append(connector)
        start, end = ends
        if start.kind != "output" or end.kind != "input":
            raise SspError(ssd_shown, element, f"must connect an output to an input, not {start.kind} to {end.kind}")
        if start.type != end.type:
            raise SspError(ssd_shown, element, f"type mismatch: {start.type} to {end.type}")
        if c.find(_q("ssc", "LinearTransformation")) is not None or c.find(_q("ssd", "LinearTransformation")) is not None:
            raise SspError(ssd_shown, element, "transformations are not supported")
        if (start.unit or None) != (end.unit or None):
            raise SspError(ssd_shown, element, f"unit mismatch: [{start.unit}] to [{end.unit}] "
                                               f"(no unit conversion is applied)")
        key = (con.end_element, con.end_connector)
        if key in inputs_connected:
            raise SspError(ssd_shown, element, f"input {key[0]}.{key[1]} is already connected")
        inputs_connected[key] = con
        connections.append(con)
    unconnected = [f"{comp.name}.{v.name}" for comp in components.values() for v in comp.variables.values()
                   if v.causality == "input" and (comp.name, v.name) not in inputs_connected]
    if unconnected:
        raise SspError(ssd_shown, "Connections", f"unconnected inputs: {', '.join(unconnected)} "
                                                 f"(every input of every component must be connected)")
    last = {c.name: list(c.parameter_sets)[-1] for c in components.values() if c.parameter_sets}
    if len(set(last.values())) > 1:
        raise SspError(ssd_shown, "ParameterBindings", "the components end with different parameter sets "
                       f"({', '.join(f'{k}: {v}' for k, v in last.items())}); bind one set per SSD and put "
                       "the others into variant SSDs")
    names = list(dict.fromkeys(last.values()))
    for other in _other_ssds(base, ssd):
        if other not in names:
            names.append(other)
    step = stop = None
    experiment = root.find(_q("ssd", "DefaultExperiment"))
    if experiment is not None:
        stop = float(experiment.get("stopTime")) if experiment.get("stopTime") else None
        fixed = experiment.find(f".//{_q('osp', 'FixedStepAlgorithm')}")
        if fixed is not None and fixed.get("baseStepSize"):
            step = float(fixed.get("baseStepSize"))
    result = SspSystem(Path(path), system.get("name"), components, connections, names, step, stop, workdir,
                       ssd.relative_to(base).as_posix())
    if parameter_set is not None:
        result.check_parameter_set(parameter_set)
    return result


def _other_ssds(base: Path, ssd: Path) -> list[str]:
    """Names of the parameter sets of the other SSDs beside ``ssd``: a variant's is its file name, the
    default SSD's (SystemStructure.ssd, or ssp/'s source SSD) that of its first binding's .ssv."""
    names = []
    for other in sorted(base.glob(f"*{SSD_SUFFIX}")):
        if other.resolve() == ssd.resolve():
            continue
        if other.name not in (SSD_IN_ARCHIVE, SOURCE_SSD.name):
            names.append(other.name[:-len(SSD_SUFFIX)])
            continue
        try:
            binding = ET.parse(other).getroot().find(f".//{_q('ssd', 'ParameterBinding')}")
            source = binding.get("source") if binding is not None else None
            if source and (base / source).is_file():
                names.insert(0, ET.parse(base / source).getroot().get("name"))
        except ET.ParseError:
            pass  # the default SSD is checked when it is read
    return [n for n in names if n]
