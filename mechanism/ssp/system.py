"""The slider-crank with the ball-bearing joint as an SSP 1.0 system, as plain data.

Two components, ``mechanism`` (SliderCrank.fmu) and ``bearing`` (BallBearing.fmu), their connectors
with units (taken from the two slaves' variable tables), the connections (eccentricity, velocity and
ring speeds to the bearing; force and tangent matrices back) and the named parameter sets
``PARAMETER_SETS`` (the paper's studies). ``mechanism.ssp.generate`` writes them as files,
``mechanism.ssp.reader`` reads and checks an archive.

Parameter sets follow SSP 1.0, which applies every ParameterBinding of an element in order (a later
one overriding an earlier one): the default SSD (``SystemStructure.ssd`` in the archive) binds ONE set per
component, the default ``DEFAULT_PARAMETER_SET``; every other set is a variant SSD of the same archive,
``<set name>.ssd`` beside it, identical but for its bindings. Each binding's .ssv carries the set's name and
every parameter of that component, so a set is complete on its own and every conforming tool ends with the
same values (``load_ssp(path, name)`` reads the variant).
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from xml.etree import ElementTree as ET

from fmu_bearing.interface import COUPLING_OUTPUT_NAMES, JOINT_INPUT_NAMES
from fmu_bearing.parameters import BearingParameters
from mechanism.systems.slider_crank import SliderCrankParameters

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)

ROOT = Path(__file__).resolve().parents[2]   # the repository (ssp/ holds the generated files)
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
    from mechanism.ssp.slaves import slider_crank_fmu as sc

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
    from mechanism.ssp.slaves import slider_crank_fmu as sc
    return {name: unit for name, (unit, _) in sc.PARAMETER_INFO.items()}


def _q(prefix: str, tag: str) -> str:
    """The qualified XML tag ``{namespace}tag`` of an SSP element."""
    return f"{{{NS[prefix]}}}{tag}"


def variant_ssd_name(set_name: str) -> str:
    """File name of the variant SSD of a parameter set (in the archive's root and in ssp/)."""
    return f"{set_name}{SSD_SUFFIX}"
