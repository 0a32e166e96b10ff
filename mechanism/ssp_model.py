"""The slider-crank with the ball-bearing joint as an SSP 1.0 system: writing, packing, reading and checking.

Three things live here, all in plain data (no simulation):

* **the system** (``SYSTEM_NAME``): two components, ``mechanism`` (SliderCrank.fmu) and ``bearing``
  (BallBearing.fmu), their connectors with units (taken from the two slaves' variable tables), the
  connections (eccentricity, velocity and ring speeds to the bearing; force and tangent matrices back)
  and the named parameter sets ``PARAMETER_SETS`` (the paper's studies);
* **the generator** (``expected_files``, ``generate``): the SSD and one .ssv per component and
  parameter set, written from the ``BearingParameters()`` and ``SliderCrankParameters()`` defaults.
  The dataclasses are the source; the files in ``ssp/`` are generated and a test checks that they
  equal what the generator produces now (``python -m mechanism ssp-generate`` rewrites them);
* **the reader** (``load_ssp``): an .ssp archive (or an .ssd in an unpacked folder) into dataclasses,
  validated before any simulation starts: the SSP 1.0 schema (the XSDs fmpy ships), the FMU resources,
  every connector against its FMU's variable (causality, type, unit), every connection (known
  connectors, output to input, same type and unit), every parameter of every set (known to the FMU,
  type, unit, the FMU's min/max, and the component's own validation). Every problem is an
  ``SspError`` naming the file, the element and the problem.

Parameter sets follow SSP 1.0, which applies every ParameterBinding of an element in order (a later
one overriding an earlier one): the default SSD (``SystemStructure.ssd`` in the archive) binds ONE set per
component, the default ``DEFAULT_PARAMETER_SET``; every other set is a variant SSD of the same archive,
``<set name>.ssd`` beside it, identical but for its bindings. Each binding's .ssv carries the set's name and
every parameter of that component, so a set is complete on its own and every conforming tool ends with the
same values (``load_ssp(path, name)`` reads the variant).
"""
from __future__ import annotations

import math
import os
import shutil
import tempfile
import zipfile
from dataclasses import dataclass, field, fields
from pathlib import Path, PurePosixPath
from xml.etree import ElementTree as ET

from fmu_bearing.interface import COUPLING_OUTPUT_NAMES, JOINT_INPUT_NAMES
from fmu_bearing.parameters import BearingParameters
from .slider_crank import SliderCrankParameters

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)

ROOT = Path(__file__).resolve().parent.parent
SOURCE_DIR = ROOT / "ssp"
SYSTEM_NAME = "SliderCrankBearing"
SOURCE_SSD = SOURCE_DIR / f"{SYSTEM_NAME}.ssd"
ARCHIVE_NAME = f"{SYSTEM_NAME}.ssp"
SSD_IN_ARCHIVE = "SystemStructure.ssd"   # the default SSD of an SSP archive (SSP 1.0, 5.3)
SSD_SUFFIX = ".ssd"                      # variant SSDs: <set name>.ssd beside it (SSP 1.0, 5.3: variants)
FMU_TYPE = "application/x-fmu-sharedlibrary"
SSV_TYPE = "application/x-ssp-parameter-set"
#: communication step of the SSD's default experiment (libcosim reads it from the OSP annotation) [s]
DEFAULT_STEP = 1e-5
DEFAULT_STOP = 0.1

MECHANISM, BEARING = "mechanism", "bearing"
#: component name -> FMU model name; the FMU is resources/<model>.fmu
COMPONENTS = {MECHANISM: "SliderCrank", BEARING: "BallBearing"}


class SspError(ValueError):
    """A malformed or inconsistent SSP: ``file``, ``element`` and ``problem`` say where and what."""

    def __init__(self, file, element: str, problem: str):
        super().__init__(f"{file}: {element}: {problem}")
        self.file, self.element, self.problem = str(file), element, problem


# ------------------------------------------------------------------------------------------------
# The system: connectors, connections, units, parameter sets
# ------------------------------------------------------------------------------------------------
def _interfaces() -> dict[str, list[tuple[str, str, str, str | None]]]:
    """component -> [(connector, kind, type, unit)], from the two slaves' variable tables."""
    from fmu_bearing.slaves import ball_bearing_fmu as bb
    from .slaves import slider_crank_fmu as sc

    mechanism = [(n, "input", "Real", u) for n, u, _ in sc.INPUTS]
    mechanism += [(n, "output", "Real", u) for n, u, _ in sc.OUTPUTS]
    bearing = [(n, "input", "Real", u) for n, u, _ in bb.INPUTS]
    bearing += [(n, "output", "Real" if u else "Integer", u) for n, u, _ in bb.FORCE_OUTPUTS]
    bearing.append((bb.CAGE_ANGLE[0], "output", "Real", bb.CAGE_ANGLE[1]))
    return {MECHANISM: mechanism, BEARING: bearing}


#: the bearing's inputs (from the mechanism) and the coupling outputs (to the mechanism), same names
BEARING_INPUTS = JOINT_INPUT_NAMES
COUPLING_OUTPUTS = COUPLING_OUTPUT_NAMES
CONNECTIONS = tuple([(MECHANISM, n, BEARING, n) for n in BEARING_INPUTS]
                    + [(BEARING, n, MECHANISM, n) for n in COUPLING_OUTPUTS])


def unit_definitions() -> dict[str, dict | None]:
    """unit -> SSP BaseUnit attributes (exponents, factor); None where there is no integer-exponent form."""
    from fmu_bearing.slaves import UNIT_DEFINITIONS
    return dict(UNIT_DEFINITIONS)


@dataclass(frozen=True)
class ParameterSetSpec:
    """A named parameter set: changes to the ``BearingParameters()`` and ``SliderCrankParameters()`` defaults."""

    name: str
    description: str
    bearing: dict = field(default_factory=dict)
    mechanism: dict = field(default_factory=dict)

    def values(self, component: str) -> dict:
        """Every parameter of ``component`` in this set: the dataclass defaults with the changes."""
        if component == BEARING:
            return BearingParameters().replace(**self.bearing).as_dict()
        params = SliderCrankParameters(**{**_asdict(SliderCrankParameters()), **self.mechanism})
        return _asdict(params)


def _asdict(obj) -> dict:
    return {f.name: getattr(obj, f.name) for f in fields(obj)}


_OVERLAP = "hypothetical: {n} balls of 8.7 mm do not fit on the 37.9 mm pitch circle (allow_ball_overlap)"
#: the paper's studies (Section 5): Table 2 at the four speeds, and 15 and 20 balls at 1200 rpm. The first is the default.
PARAMETER_SETS = (
    ParameterSetSpec("BB1B420205-1200rpm", "SKF BB1B420205 (Table 2, 8 balls), Table 1 slider-crank at 1200 rpm",
                     mechanism={"rpm": 1200.0}),
    ParameterSetSpec("BB1B420205-300rpm", "SKF BB1B420205 (Table 2, 8 balls), Table 1 slider-crank at 300 rpm",
                     mechanism={"rpm": 300.0}),
    ParameterSetSpec("BB1B420205-600rpm", "SKF BB1B420205 (Table 2, 8 balls), Table 1 slider-crank at 600 rpm",
                     mechanism={"rpm": 600.0}),
    ParameterSetSpec("BB1B420205-900rpm", "SKF BB1B420205 (Table 2, 8 balls), Table 1 slider-crank at 900 rpm",
                     mechanism={"rpm": 900.0}),
    ParameterSetSpec("BB1B420205-15balls-1200rpm",
                     "Table 2 geometry with 15 balls (" + _OVERLAP.format(n=15) + "), 1200 rpm",
                     bearing={"n_balls": 15, "allow_ball_overlap": True}, mechanism={"rpm": 1200.0}),
    ParameterSetSpec("BB1B420205-20balls-1200rpm",
                     "Table 2 geometry with 20 balls (" + _OVERLAP.format(n=20) + "), 1200 rpm",
                     bearing={"n_balls": 20, "allow_ball_overlap": True}, mechanism={"rpm": 1200.0}),
)
DEFAULT_PARAMETER_SET = PARAMETER_SETS[0].name


def ssv_path(set_name: str, component: str) -> str:
    """Path of a parameter set's .ssv for one component, relative to the SSD (and to ssp/)."""
    return f"resources/{set_name}/{component}.ssv"


def parameter_units(component: str) -> dict[str, str]:
    """parameter -> unit ("" for Integer/Boolean) of a component's parameters."""
    if component == BEARING:
        return {f.name: f.metadata.get("unit", "") for f in fields(BearingParameters)}
    from .slaves import slider_crank_fmu as sc
    return {name: unit for name, (unit, _) in sc.PARAMETER_INFO.items()}


# ------------------------------------------------------------------------------------------------
# The generator
# ------------------------------------------------------------------------------------------------
def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _format(value) -> tuple[str, str]:
    """(SSV type element, value text) of a Python parameter value."""
    if isinstance(value, bool):
        return "Boolean", "true" if value else "false"
    if isinstance(value, int):
        return "Integer", str(value)
    return "Real", repr(float(value))


def _units_element(prefix: str, names, definitions) -> ET.Element:
    units = ET.Element(_q(prefix, "Units"))
    for name in sorted(names):
        unit = ET.SubElement(units, _q("ssc", "Unit"), {"name": name})
        attrs = {k: repr(float(v)) if k in ("factor", "offset") else str(v) for k, v in definitions[name].items()}
        ET.SubElement(unit, _q("ssc", "BaseUnit"), attrs)
    return units


def _to_text(root: ET.Element) -> str:
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


_GENERATED = "generated by `python -m mechanism ssp-generate` from the dataclass defaults: do not edit"


def ssv_text(spec: ParameterSetSpec, component: str) -> str:
    """The .ssv of one component in one parameter set."""
    definitions = unit_definitions()
    units = parameter_units(component)
    root = ET.Element(_q("ssv", "ParameterSet"), {
        "version": "1.0", "name": spec.name, "description": f"{component}: {spec.description}",
        "generationTool": _GENERATED})
    params = ET.SubElement(root, _q("ssv", "Parameters"))
    used = set()
    for name, value in spec.values(component).items():
        kind, text = _format(value)
        p = ET.SubElement(params, _q("ssv", "Parameter"), {"name": name})
        attrs = {"value": text}
        unit = units.get(name, "")
        if kind == "Real" and unit and definitions.get(unit) is not None:
            attrs["unit"] = unit
            used.add(unit)
        ET.SubElement(p, _q("ssv", kind), attrs)
    if used:
        root.append(_units_element("ssv", used, definitions))
    return _to_text(root)


def variant_ssd_name(set_name: str) -> str:
    """File name of the variant SSD of a parameter set (in the archive's root and in ssp/)."""
    return f"{set_name}{SSD_SUFFIX}"


def ssd_text(spec: ParameterSetSpec | None = None) -> str:
    """The System Structure Description with ONE parameter binding per component, that of ``spec`` (default:
    the default set): components, connectors, connections, parameter bindings, units."""
    spec = spec or PARAMETER_SETS[0]
    definitions = unit_definitions()
    variant = "" if spec.name == DEFAULT_PARAMETER_SET else f" Variant SSD of parameter set {spec.name}."
    root = ET.Element(_q("ssd", "SystemStructureDescription"), {
        "version": "1.0", "name": SYSTEM_NAME,
        "description": "Slider-crank (Xu et al. 2012, Table 1) with a deep-groove ball bearing with clearance "
                       "(Table 2) as the crank-rod joint: two FMUs coupled through force and tangent matrices. "
                       f"Parameter set: {spec.name} ({spec.description}).{variant}",
        "generationTool": _GENERATED})
    system = ET.SubElement(root, _q("ssd", "System"), {"name": SYSTEM_NAME})
    elements = ET.SubElement(system, _q("ssd", "Elements"))
    used = set()
    for component, connectors in _interfaces().items():
        model = COMPONENTS[component]
        comp = ET.SubElement(elements, _q("ssd", "Component"), {
            "name": component, "type": FMU_TYPE, "source": f"resources/{model}.fmu"})
        cons = ET.SubElement(comp, _q("ssd", "Connectors"))
        for name, kind, vtype, unit in connectors:
            con = ET.SubElement(cons, _q("ssd", "Connector"), {"name": name, "kind": kind})
            ET.SubElement(con, _q("ssc", vtype), {"unit": unit} if unit else {})
            if unit:
                used.add(unit)
        bindings = ET.SubElement(comp, _q("ssd", "ParameterBindings"))
        ET.SubElement(bindings, _q("ssd", "ParameterBinding"), {
            "type": SSV_TYPE, "source": ssv_path(spec.name, component)})
    connections = ET.SubElement(system, _q("ssd", "Connections"))
    for start, start_con, end, end_con in CONNECTIONS:
        ET.SubElement(connections, _q("ssd", "Connection"), {
            "startElement": start, "startConnector": start_con, "endElement": end, "endConnector": end_con})
    root.append(_units_element("ssd", used, definitions))
    experiment = ET.SubElement(root, _q("ssd", "DefaultExperiment"),
                               {"startTime": "0.0", "stopTime": repr(DEFAULT_STOP)})
    annotations = ET.SubElement(experiment, _q("ssd", "Annotations"))
    annotation = ET.SubElement(annotations, _q("ssc", "Annotation"), {"type": "com.opensimulationplatform"})
    algorithm = ET.SubElement(annotation, _q("osp", "Algorithm"))
    ET.SubElement(algorithm, _q("osp", "FixedStepAlgorithm"), {"baseStepSize": repr(DEFAULT_STEP)})
    return _to_text(root)


def expected_files() -> dict[str, str]:
    """Every generated file of ssp/, relative path -> text (what ``generate`` writes): the default SSD, one
    variant SSD per other parameter set, and the .ssv files."""
    files = {SOURCE_SSD.name: ssd_text()}
    for spec in PARAMETER_SETS[1:]:
        files[variant_ssd_name(spec.name)] = ssd_text(spec)
    for spec in PARAMETER_SETS:
        for component in COMPONENTS:
            files[ssv_path(spec.name, component)] = ssv_text(spec, component)
    return files


def generate(dest: str | Path = SOURCE_DIR) -> list[Path]:
    """Write the SSD and the .ssv files into ``dest`` (default ssp/); return the paths written."""
    dest = Path(dest)
    written = []
    for rel, text in expected_files().items():
        path = dest / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        written.append(path)
    return written


def pack(out: str | Path, fmus: dict[str, str | Path], source: str | Path = SOURCE_DIR) -> Path:
    """Pack the SSD of ``source`` (as SystemStructure.ssd), its variant SSDs (``<set>.ssd``), its .ssv files and
    the FMUs (model name -> path) into the archive ``out``; the archive is checked with ``load_ssp`` (every
    variant) before it replaces ``out``."""
    source, out = Path(source), Path(out)
    ssd = source / SOURCE_SSD.name
    if not ssd.is_file():
        raise SspError(ssd, "SystemStructureDescription", "not found (run `python -m mechanism ssp-generate`)")
    missing = [m for m in COMPONENTS.values() if m not in fmus or not Path(fmus[m]).is_file()]
    if missing:
        raise SspError(out, "resources", f"FMU(s) {missing} not built (run `python build_fmu.py`)")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(ssd, SSD_IN_ARCHIVE)
        variants = sorted(p for p in source.glob(f"*{SSD_SUFFIX}") if p.name != ssd.name)
        for variant in variants:
            z.write(variant, variant.name)
        for ssv in sorted((source / "resources").rglob("*.ssv")):
            z.write(ssv, ssv.relative_to(source).as_posix())
        for model, path in sorted(fmus.items()):
            z.write(path, f"resources/{model}.fmu")
    try:
        with load_ssp(tmp):
            pass
        for variant in variants:
            with load_ssp(tmp, variant.name[:-len(SSD_SUFFIX)]):
                pass
    except Exception:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, out)
    return out


# ------------------------------------------------------------------------------------------------
# The reader
# ------------------------------------------------------------------------------------------------
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
        problems = "; ".join(f"line {e.line}: {e.message}" for e in list(xsd.error_log)[:3])
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
        from .exchange import bearing_parameters
        capacity = component.variables.get("n_balls")
        try:
            validate(bearing_parameters(values), capacity=None if capacity is None or capacity.max is None
                     else int(capacity.max))
        except BearingParameterError as err:
            raise SspError(shown, f"Parameter '{err.name}'", f"value {err.value!r} out of range: {err.reason}") from None
    elif component.model_name == "SliderCrank":
        from .slaves.slider_crank_fmu import POSITIVE
        for name in POSITIVE:
            if name in values and not values[name] > 0.0:
                raise SspError(shown, f"Parameter '{name}'", f"value {values[name]!r} out of range: must be positive")


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
        fmu = (base / source).resolve()
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
            ssv = base / src
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
