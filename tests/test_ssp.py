"""The SSP of the slider-crank with the ball bearing: generated files, schema, reading, bad input,
the SliderCrank FMU, and our master on the SSP (``run --ssp``)."""
from __future__ import annotations

from dataclasses import replace

import argparse
import math
import re
import shutil
import zipfile

from pathlib import Path

import numpy as np
import pytest

import build_fmu
from conftest import built_fmu
from fmu_bearing.parameters import BearingParameters
from mechanism import ssp as sm
from mechanism.ssp import config as ssp_config
from mechanism.ssp import tools as ssp_tools
from mechanism.ssp.system import NS, SSV_TYPE
from mechanism.systems.slider_crank import SliderCrankParameters

H = 1e-5
T_SHORT = 0.002       # s: 200 steps, for the quick checks


@pytest.fixture(scope="session")
def slider_crank_fmu(tmp_path_factory) -> Path:
    return build_fmu.build(tmp_path_factory.mktemp("fmu_SliderCrank"), names=["SliderCrank"], verbose=False)["SliderCrank"]


@pytest.fixture(scope="session")
def ssp_archive(tmp_path_factory, slider_crank_fmu) -> Path:
    """dist-like SliderCrankBearing.ssp packed from ssp/ and freshly built FMUs."""
    bearing = built_fmu("BallBearing", tmp_path_factory)
    out = tmp_path_factory.mktemp("ssp") / sm.ARCHIVE_NAME
    return sm.pack(out, {"SliderCrank": slider_crank_fmu, "BallBearing": bearing})


# ----------------------------------------------------------------------------------------------
# generated files and schema
# ----------------------------------------------------------------------------------------------
def test_committed_ssp_files_equal_what_the_dataclass_defaults_produce():
    """The dataclasses are the source: ssp/ must be what `python -m mechanism ssp-generate` writes."""
    expected = sm.expected_files()
    on_disk = {p.relative_to(sm.SOURCE_DIR).as_posix() for p in sm.SOURCE_DIR.rglob("*.ss[dv]")}
    assert on_disk == set(expected), "ssp/ has stale or missing files: run `python -m mechanism ssp-generate`"
    for rel, text in expected.items():
        assert (sm.SOURCE_DIR / rel).read_text(encoding="utf-8") == text, \
            f"ssp/{rel} drifted from the dataclass defaults: run `python -m mechanism ssp-generate`"


def test_parameter_sets_hold_the_dataclass_defaults(ssp_archive):
    with sm.load_ssp(ssp_archive) as system:
        default = system.parameters()
        assert system.parameter_set_names[0] == sm.DEFAULT_PARAMETER_SET
        assert sorted(system.parameter_set_names) == sorted(s.name for s in sm.PARAMETER_SETS)
        assert system.ssd == sm.SSD_IN_ARCHIVE
        assert default["bearing"] == BearingParameters().as_dict()
        assert default["mechanism"] == {k: getattr(SliderCrankParameters(), k) for k in default["mechanism"]}
    for rpm in (300, 600, 900, 1200):
        with sm.load_ssp(ssp_archive, f"BB1B420205-{rpm}rpm") as system:
            values = system.parameters(f"BB1B420205-{rpm}rpm")
            assert values["mechanism"]["rpm"] == rpm and values["bearing"] == BearingParameters().as_dict()
            assert system.ssd == (sm.SSD_IN_ARCHIVE if rpm == 1200 else f"BB1B420205-{rpm}rpm.ssd")
    for n in (15, 20):
        with sm.load_ssp(ssp_archive, f"BB1B420205-{n}balls-1200rpm") as system:
            bearing = system.parameters()["bearing"]
            assert bearing == BearingParameters(n_balls=n, allow_ball_overlap=True).as_dict()
            with pytest.raises(sm.SspError, match="read the variant with load_ssp"):
                system.parameters(sm.DEFAULT_PARAMETER_SET)


def _bindings(ssd_text: str) -> dict[str, list[str]]:
    """component -> the .ssv sources of its ParameterBindings, in order."""
    import xml.etree.ElementTree as ET
    root = ET.fromstring(ssd_text.encode())
    return {c.get("name"): [b.get("source") for b in c.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS)]
            for c in root.findall("ssd:System/ssd:Elements/ssd:Component", NS)}


def test_default_ssd_binds_one_set_per_component_and_variant_ssds_the_others(ssp_archive):
    """SSP 1.0 applies every binding of a component in order: with one binding per component in every SSD,
    each conforming tool ends with the same set. The variants differ from the default SSD only there."""
    with zipfile.ZipFile(ssp_archive) as z:
        ssds = {n: z.read(n).decode() for n in z.namelist() if n.endswith(".ssd")}
        assert "/" not in "".join(ssds)                      # all at the root of the archive
        expected = {sm.SSD_IN_ARCHIVE: sm.DEFAULT_PARAMETER_SET}
        expected.update({sm.variant_ssd_name(s.name): s.name for s in sm.PARAMETER_SETS[1:]})
        assert set(ssds) == set(expected)
        strip = lambda t: re.sub(r'(<ssd:ParameterBindings>.*?</ssd:ParameterBindings>|description="[^"]*")', "",  # noqa: E731
                                 t, flags=re.S)
        for member, set_name in expected.items():
            bindings = _bindings(ssds[member])
            assert bindings == {c: [sm.ssv_path(set_name, c)] for c in sm.COMPONENTS}, member
            for c, (source,) in bindings.items():
                assert f'name="{set_name}"' in z.read(source).decode()
            assert strip(ssds[member]) == strip(ssds[sm.SSD_IN_ARCHIVE]), member
    for spec in sm.PARAMETER_SETS[1:]:
        sm.validate_schema(sm.SOURCE_DIR / sm.variant_ssd_name(spec.name), "SystemStructureDescription.xsd")


def test_several_bindings_are_applied_in_order_the_last_set_wins(ssp_archive, tmp_path):
    """The SSP 1.0 reading of an SSD with every set bound to each component (this project's SSD until
    issue 13): all bindings applied in order, so the last set's values."""
    def all_bindings(text):
        sources = "".join(f'<ssd:ParameterBinding type="{SSV_TYPE}" source="{sm.ssv_path(s.name, "{c}")}" />'
                          for s in sm.PARAMETER_SETS)
        return re.sub(r'(<ssd:Component name="(\w+)".*?<ssd:ParameterBindings>).*?(</ssd:ParameterBindings>)',
                      lambda m: m.group(1) + sources.replace("{c}", m.group(2)) + m.group(3), text, flags=re.S)

    six = _edit(ssp_archive, tmp_path, SSD, edit=all_bindings)
    with sm.load_ssp(six) as system:
        assert all(len(c.parameter_sets) == len(sm.PARAMETER_SETS) for c in system.components.values())
        assert system.parameter_set_names[0] == sm.PARAMETER_SETS[-1].name
        assert system.parameters()["bearing"] == sm.PARAMETER_SETS[-1].values("bearing")


def test_ssd_and_ssv_validate_against_the_ssp_1_0_schema(ssp_archive):
    from fmpy.ssp.ssd import read_ssd, read_ssv
    ssd = read_ssd(str(ssp_archive), validate=True)          # fmpy validates against the SSP schema it ships
    assert {c.name: c.source for c in ssd.system.elements} == {
        "mechanism": "resources/SliderCrank.fmu", "bearing": "resources/BallBearing.fmu"}
    assert len(ssd.system.connections) == len(sm.CONNECTIONS)
    for spec in sm.PARAMETER_SETS:
        for component in sm.COMPONENTS:
            pset = read_ssv(str(ssp_archive), resource=sm.ssv_path(spec.name, component), validate=True)
            assert pset.name == spec.name
    sm.validate_schema(sm.SOURCE_SSD, "SystemStructureDescription.xsd")


def test_pyssp_standard_reads_the_same_parameter_values():
    pyssp = pytest.importorskip("pyssp_standard", reason="pyssp-standard is not installed (pip install pyssp-standard)")
    for spec in sm.PARAMETER_SETS[:1] + sm.PARAMETER_SETS[-1:]:
        for component in sm.COMPONENTS:
            with pyssp.SSV(sm.SOURCE_DIR / sm.ssv_path(spec.name, component)) as ssv:
                read = {p["name"]: p["type_value"].parameter["value"] for p in ssv.parameters}
            expected = spec.values(component)
            assert set(read) == set(expected)
            for name, value in expected.items():
                got = read[name]
                if isinstance(value, bool):
                    assert str(got).lower() == str(value).lower()
                else:
                    assert float(got) == pytest.approx(float(value), rel=1e-15)


def test_load_ssp_reads_connectors_with_units_and_connections(ssp_archive):
    with sm.load_ssp(ssp_archive) as system:
        mech, bear = system.components["mechanism"], system.components["bearing"]
        assert (mech.model_name, bear.model_name) == ("SliderCrank", "BallBearing")
        units = {name: c.unit for name, c in {**mech.connectors, **bear.connectors}.items()}
        assert units["e_x"] == "m" and units["v_y"] == "m/s" and units["omega_inner"] == "rad/s"
        assert units["F_x"] == "N" and units["stiffness_xy"] == "N/m" and units["damping_yy"] == "N.s/m"
        assert len(system.connections) == 14 and system.step_size == H
        assert all(bear.connectors[c.end_connector].kind == "input" for c in system.connections
                   if c.end_element == "bearing")
        assert system.workdir.is_dir() and mech.fmu.is_file()
    assert system.workdir is None


# ----------------------------------------------------------------------------------------------
# bad input: each problem named with its file and element, before any simulation
# ----------------------------------------------------------------------------------------------
def _edit(archive: Path, tmp_path: Path, member: str, edit=None, drop: bool = False) -> Path:
    out = tmp_path / "bad.ssp"
    with zipfile.ZipFile(archive) as src, zipfile.ZipFile(out, "w") as dst:
        for item in src.infolist():
            if item.filename == member and drop:
                continue
            data = src.read(item.filename)
            if item.filename == member and edit is not None:
                text = data.decode("utf-8")
                changed = edit(text)
                assert changed != text, f"the edit did not change {member}"
                data = changed.encode("utf-8")
            dst.writestr(item, data)
    return out


SSD = sm.SSD_IN_ARCHIVE
BEARING_SSV = sm.ssv_path(sm.DEFAULT_PARAMETER_SET, "bearing")
MECH_SSV = sm.ssv_path(sm.DEFAULT_PARAMETER_SET, "mechanism")


def _param(name, kind, old, new):
    return lambda t: t.replace(f'<ssv:Parameter name="{name}">\n      <ssv:{kind} value="{old}"',
                               f'<ssv:Parameter name="{name}">\n      <ssv:{kind} value="{new}"')


BAD = {
    "missing FMU resource": (
        dict(member="resources/BallBearing.fmu", drop=True), SSD, "Component 'bearing'", "missing FMU resource"),
    "unknown connector on a component": (
        dict(member=SSD, edit=lambda t: t.replace('<ssd:Connector name="slider_v"', '<ssd:Connector name="slider_w"')),
        SSD, "Connector 'mechanism.slider_w'", "unknown connector"),
    "unknown connector in a connection": (
        dict(member=SSD, edit=lambda t: t.replace('startConnector="omega_outer" endElement="bearing"',
                                                  'startConnector="omega_housing" endElement="bearing"')),
        SSD, "Connection mechanism.omega_housing -> bearing.omega_outer", "unknown connector"),
    "unit mismatch on a connection": (
        dict(member=SSD, edit=lambda t: t.replace('endElement="bearing" endConnector="e_x"',
                                                  'endElement="bearing" endConnector="v_x"')),
        SSD, "Connection mechanism.e_x -> bearing.v_x", "unit mismatch: [m] to [m/s]"),
    "connector unit unlike the FMU's": (
        dict(member=SSD, edit=lambda t: t.replace('<ssd:Connector name="F_x" kind="input">\n            <ssc:Real unit="N"',
                                                  '<ssd:Connector name="F_x" kind="input">\n            <ssc:Real unit="kN"')),
        SSD, "Connector 'mechanism.F_x'", "unit mismatch"),
    "parameter not in the FMU": (
        dict(member=BEARING_SSV, edit=lambda t: t.replace('name="n_balls"', 'name="ball_count"')),
        BEARING_SSV, "Parameter 'ball_count'", "parameter not in the FMU"),
    "value above the FMU's max": (
        dict(member=BEARING_SSV, edit=_param("n_balls", "Integer", 8, 50)),
        BEARING_SSV, "Parameter 'n_balls'", "out of range: above the FMU's max 20"),
    "value below the FMU's min": (
        dict(member=MECH_SSV, edit=_param("crank_mass", "Real", 0.3, -0.3)),
        MECH_SSV, "Parameter 'crank_mass'", "out of range: below the FMU's min 0"),
    "value outside the bearing's validation": (
        dict(member=BEARING_SSV, edit=_param("poisson_ratio", "Real", 0.3, 0.7)),
        BEARING_SSV, "Parameter 'poisson_ratio'", "out of range: must lie in (0, 0.5)"),
    "balls that do not fit without allow_ball_overlap": (
        dict(member=sm.ssv_path("BB1B420205-15balls-1200rpm", "bearing"),
             edit=_param("allow_ball_overlap", "Boolean", "true", "false")),
        sm.ssv_path("BB1B420205-15balls-1200rpm", "bearing"), "Parameter 'n_balls'", "do not fit"),
    "parameter type unlike the FMU's": (
        dict(member=BEARING_SSV, edit=lambda t: t.replace('<ssv:Integer value="8" />', '<ssv:Real value="8.0" />')),
        BEARING_SSV, "Parameter 'n_balls'", "type Real does not match the FMU's Integer"),
    "schema violation": (
        dict(member=SSD, edit=lambda t: t.replace("<ssd:Connections>", "<ssd:Wires>").replace("</ssd:Connections>", "</ssd:Wires>")),
        SSD, "schema SystemStructureDescription.xsd", "does not validate"),
    "malformed XML": (
        dict(member=MECH_SSV, edit=lambda t: t.replace("</ssv:Parameters>", "</ssv:Parameter>")),
        MECH_SSV, "XML", "not well-formed"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_ssp_is_rejected_naming_file_element_and_problem(ssp_archive, tmp_path, case):
    edit, member, element, problem = BAD[case]
    bad = _edit(ssp_archive, tmp_path, **edit)
    parts = member.split("/")   # an .ssv of a variant set is read with the variant SSD
    parameter_set = parts[1] if member.endswith(".ssv") and parts[1] != sm.DEFAULT_PARAMETER_SET else None
    with pytest.raises(sm.SspError) as info:
        sm.load_ssp(bad, parameter_set)
    err = info.value
    assert err.file == f"{bad}!/{member}", str(err)
    assert err.element == element, str(err)
    assert problem in err.problem, str(err)
    assert str(err).startswith(f"{bad}!/{member}: {element}: ")
    assert not list(tmp_path.glob("ssp_*")), "the unpacked folder is removed on error"


def test_bad_ssp_stops_the_tools_and_the_master_before_any_simulation(ssp_archive, tmp_path, monkeypatch):
    edit, member, element, problem = BAD["unit mismatch on a connection"]
    bad = _edit(ssp_archive, tmp_path, **edit)
    import fmpy.ssp.simulation
    monkeypatch.setattr(fmpy.ssp.simulation, "simulate_ssp", lambda *a, **k: pytest.fail("simulation started"))
    with pytest.raises(sm.SspError, match="unit mismatch"):
        ssp_tools.simulate_with("fmpy", bad)
    with pytest.raises(sm.SspError, match="unit mismatch"):
        ssp_config.config_from_ssp(bad)


def test_unknown_parameter_set_and_non_archive_are_rejected(ssp_archive, tmp_path):
    with pytest.raises(sm.SspError, match=r"Component 'mechanism'|no parameter set named 'BB1B420205-42rpm'") as info:
        sm.load_ssp(ssp_archive, "BB1B420205-42rpm")
    assert "BB1B420205-1200rpm" in str(info.value)       # the message lists the sets
    not_zip = tmp_path / "x.ssp"
    not_zip.write_text("hello")
    with pytest.raises(sm.SspError, match="not an SSP archive"):
        sm.load_ssp(not_zip)
    no_ssd = _edit(ssp_archive, tmp_path, SSD, drop=True)
    with pytest.raises(sm.SspError, match="SystemStructure.ssd: missing from the archive"):
        sm.load_ssp(no_ssd)
    with pytest.raises(sm.SspError, match="missing FMU resource"):
        sm.load_ssp(sm.SOURCE_SSD)   # the source folder has no FMUs


# ----------------------------------------------------------------------------------------------
# our master on the SSP: `run --ssp FILE --parameter-set NAME`
# ----------------------------------------------------------------------------------------------
def _run_args(*argv):
    from mechanism.cli import add_run_arguments
    parser = argparse.ArgumentParser()
    add_run_arguments(parser)
    ssp_config.add_ssp_arguments(parser)
    return parser.parse_args(list(argv))


def test_run_ssp_maps_the_parameter_set_onto_run_config(ssp_archive):
    args = _run_args("--ssp", str(ssp_archive), "--parameter-set", "BB1B420205-20balls-1200rpm",
                     "--revs", "0.01", "--quiet")
    config = ssp_config.config_from_ssp_args(args)
    assert config.rpm == 1200.0 and config.joint == "bearing" and config.revs == 0.01
    assert config.settings == BearingParameters(n_balls=20, allow_ball_overlap=True).as_dict()
    assert Path(config.fmu).is_file() and Path(config.fmu).name == "BallBearing.fmu"
    config600, system = ssp_config.config_from_ssp(ssp_archive, "BB1B420205-600rpm")
    system.close()
    assert config600.rpm == 600.0
    with pytest.raises(ValueError, match="drop --rpm, --set"):
        ssp_config.config_from_ssp_args(_run_args("--ssp", str(ssp_archive), "--rpm", "600", "--set", "n_balls=9"))


def test_run_ssp_refuses_slider_crank_values_run_config_cannot_carry(ssp_archive, tmp_path):
    bad = _edit(ssp_archive, tmp_path, MECH_SSV, edit=_param("crank_length", "Real", 0.05, 0.06))
    with pytest.raises(sm.SspError, match="Parameter 'crank_length'.*RunConfig carries rpm and gravity only"):
        ssp_config.config_from_ssp(bad)


# ----------------------------------------------------------------------------------------------
# the SliderCrank FMU
# ----------------------------------------------------------------------------------------------
def test_slider_crank_fmu_is_valid_and_declares_the_interface(slider_crank_fmu):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(slider_crank_fmu)) == []
    md = read_model_description(str(slider_crank_fmu))
    v = {x.name: x for x in md.modelVariables}
    assert md.modelName == "SliderCrank" and md.coSimulation.canGetAndSetFMUstate
    for name, unit in (("F_x", "N"), ("stiffness_xx", "N/m"), ("damping_xy", "N.s/m")):
        assert v[name].causality == "input" and v[name].unit == unit
    for name in ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer", "slider_x", "slider_v",
                 "slider_a", "crank_angle", "crank_moment"):
        assert v[name].causality == "output" and v[name].initial == "calculated"
    assert v["rpm"].causality == "parameter" and float(v["rpm"].start) == 1200.0
    assert float(v["crank_mass"].start) == SliderCrankParameters().crank_mass
    with zipfile.ZipFile(slider_crank_fmu) as z:
        names = z.namelist()
        slave = z.read("resources/slavemodule.txt").decode()   # sealed: private names (build_fmu.seal)
    tag = slave.rsplit("_", 1)[1]
    assert f"resources/_mechanism_{tag}/multibody/solver.py" in names and f"resources/slider_crank_fmu_{tag}.py" in names


class _Pair:
    """The two FMUs through fmpy's FMU2Slave, stepped by a small fixed-step master (Jacobi or Gauss-Seidel)."""

    MO = ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")
    BO = ("F_x", "F_y", "stiffness_xx", "stiffness_xy", "stiffness_yy", "damping_xx", "damping_xy", "damping_yy")

    def __init__(self, mech_fmu, bearing_fmu, mech_ints=None):
        self.dirs = []
        self.mech, self.mv = self._instantiate(mech_fmu, "mechanism", mech_ints or {})
        self.bear, self.bv = self._instantiate(bearing_fmu, "bearing", {})
        self.step = 0

    def _instantiate(self, path, name, ints):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        md = read_model_description(str(path))
        d = extract(str(path))
        self.dirs.append(d)
        f = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName=name)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        f.instantiate()
        f.setupExperiment(startTime=0.0)
        f.enterInitializationMode()
        for k, value in ints.items():
            f.setInteger([vr[k]], [value])
        f.exitInitializationMode()
        return f, vr

    def run(self, n, h=H, gauss_seidel=False, record=("slider_x", "e_x", "e_y")):
        mech, bear, mv, bv = self.mech, self.bear, self.mv, self.bv
        u_m = mech.getReal([mv[x] for x in self.MO])
        u_b = bear.getReal([bv[x] for x in self.BO])
        out = []
        for _ in range(n):
            t = self.step * h
            self.step += 1
            mech.setReal([mv[x] for x in self.BO], u_b)
            mech.doStep(t, h)
            if gauss_seidel:
                u_m = mech.getReal([mv[x] for x in self.MO])
            bear.setReal([bv[x] for x in self.MO], u_m)
            bear.doStep(t, h)
            u_m = mech.getReal([mv[x] for x in self.MO])
            u_b = bear.getReal([bv[x] for x in self.BO])
            out.append(mech.getReal([mv[x] for x in record]) + list(u_b[:2]))
        return np.array(out)

    def close(self):
        for f in (self.mech, self.bear):
            f.terminate()
            f.freeInstance()
        for d in self.dirs:
            shutil.rmtree(d, ignore_errors=True)


def test_slider_crank_fmu_with_gauss_seidel_ordering_reproduces_our_master(ssp_archive):
    """force_lag_steps = 0 and a Gauss-Seidel loop: the two-FMU system is our master's jacobian-drift
    co-simulation, to rounding (the same core, the same BallBearing FMU)."""
    from mechanism.run import run
    config, system = ssp_config.config_from_ssp(ssp_archive, revs=T_SHORT * 20.0, step=H,   # the pair steps H
                                                  progress=False)  # 0.04 rev = 2 ms
    try:
        ref = run(replace(config, scheme="jacobian-drift"))   # the default iterates with rollback since issue 12
        pair = _Pair(system.components["mechanism"].fmu, system.components["bearing"].fmu, {"force_lag_steps": 0})
        try:
            got = pair.run(len(ref["time"]) - 1, gauss_seidel=True)
        finally:
            pair.close()
    finally:
        system.close()
    assert ref.ok
    for col, key in ((0, "slider_x"), (1, "e_x"), (2, "e_y"), (3, "F_x"), (4, "F_y")):
        scale = np.max(np.abs(ref[key]))
        assert np.max(np.abs(got[:, col] - ref[key][1:])) <= 1e-9 * scale, key


def test_slider_crank_fmu_state_round_trip(ssp_archive):
    with sm.load_ssp(ssp_archive) as system:
        pair = _Pair(system.components["mechanism"].fmu, system.components["bearing"].fmu)
        try:
            pair.run(50)
            mech_state, bear_state = pair.mech.getFMUstate(), pair.bear.getFMUstate()
            serialized = pair.mech.serializeFMUstate(mech_state)
            first = pair.run(30)
            pair.step -= 30
            pair.mech.setFMUstate(pair.mech.deSerializeFMUstate(serialized))
            pair.bear.setFMUstate(bear_state)
            again = pair.run(30)
        finally:
            pair.close()
    assert np.array_equal(first, again)


def test_two_fmu_jacobi_is_stable_at_1e_5_with_the_tangent_inputs_and_not_without(ssp_archive, tmp_path):
    """fmpy.ssp (fixed-step Jacobi) at h = 1e-5 s, 0.2 rev at 1200 rpm: stable with the stiffness and
    damping connections; without them (zero-order hold) the eccentricity diverges within ~150 steps."""
    result = ssp_tools.simulate_with("fmpy", ssp_archive, step=H, t_end=0.01)
    e = np.hypot(result["mechanism.e_x"], result["mechanism.e_y"])
    assert np.all(np.isfinite(e)) and 20e-6 < e.max() < 45e-6      # monolithic reference: 30.6 µm
    tangent = ("stiffness_xx", "stiffness_xy", "stiffness_yy", "damping_xx", "damping_xy", "damping_yy")

    def zoh(text):
        for name in tangent:
            text = re.sub(rf'\s*<ssd:Connection startElement="bearing" startConnector="{name}"[^>]*/>', "", text)
            text = re.sub(rf'\s*<ssd:Connector name="{name}" kind="input">\s*<ssc:Real unit="[^"]*" />\s*'
                          rf'</ssd:Connector>', "", text)
        return text

    held = _edit(ssp_archive, tmp_path, SSD, edit=zoh)
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import Parameter, ParameterSet
    pset = ParameterSet(name="zoh", parameters=[Parameter(name="mechanism.force_drift", value=False)])
    with pytest.raises(Exception, match="fmi2DoStep"):
        simulate_ssp(str(held), stop_time=0.01, step_size=H, parameter_set=pset)


def test_ssp_cli_generate_check_and_pack(ssp_archive, tmp_path, capsys):
    from mechanism.cli import main
    assert main(["ssp-generate", "--check"]) == 0
    fmu_dir = tmp_path / "fmus"
    fmu_dir.mkdir()
    with sm.load_ssp(ssp_archive) as system:
        for c in system.components.values():
            shutil.copy(c.fmu, fmu_dir / f"{c.model_name}.fmu")
    out = tmp_path / "out.ssp"
    assert main(["ssp-pack", "--no-build", "--fmu-dir", str(fmu_dir), "--out", str(out)]) == 0
    assert out.is_file() and "packed" in capsys.readouterr().out
    (fmu_dir / "SliderCrank.fmu").unlink()
    assert main(["ssp-pack", "--no-build", "--fmu-dir", str(fmu_dir), "--out", str(out)]) == 2
    assert "not built" in capsys.readouterr().err
    assert math.isfinite(out.stat().st_size)


# ----------------------------------------------------------------------------------------------
# every tool applies the same parameter set: fmpy.ssp, libcosim, ecos (issue 13, item 7)
# ----------------------------------------------------------------------------------------------
def _tool_missing(tool: str) -> str | None:
    try:
        if tool == "libcosim":
            import libcosimpy.CosimExecution  # noqa: F401
        elif tool == "ecos":
            import ecospy  # noqa: F401
    except (ImportError, OSError) as err:   # ecospy: libtbb.so.12 missing (apt-get install libtbb12)
        return f"{tool} does not load here ({err}); pip install '.[tools]'"
    return None


def test_fmpy_libcosim_and_ecos_apply_the_same_parameter_set(ssp_archive, monkeypatch):
    """Each tool reads the set from the SSD itself (default: SystemStructure.ssd; a named set: its variant
    SSD): n_balls read back from the bearing instance, and the force after 30 steps at 1e-5 s, agree."""
    import fmpy.ssp.simulation as fmpy_sim
    missing = {tool: _tool_missing(tool) for tool in ssp_tools.TOOLS}
    if any(missing.values()):
        pytest.skip("; ".join(r for r in missing.values() if r))
    read_back = {}
    free = fmpy_sim.free_fmu

    def free_after_reading_n_balls(component):   # fmpy.ssp records connectors only: read the parameter back
        if component.name == "bearing":
            read_back["n_balls"] = fmpy_sim.get_value(component, "n_balls")
        free(component)

    monkeypatch.setattr(fmpy_sim, "free_fmu", free_after_reading_n_balls)
    record = ("bearing.F_x", "bearing.F_y", "bearing.loaded_balls", "bearing.max_ball_load")
    peak = {}
    for set_name, n_balls in ((None, 8), ("BB1B420205-15balls-1200rpm", 15)):
        runs = {}
        for tool in ssp_tools.TOOLS:
            extra = () if tool == "fmpy" else ("bearing.n_balls",)
            runs[tool] = ssp_tools.simulate_with(tool, ssp_archive, set_name, step=H, t_end=30 * H,
                                               record=record + extra)
        assert read_back["n_balls"] == n_balls
        assert np.all(runs["libcosim"]["bearing.n_balls"] == n_balls)
        assert np.all(runs["ecos"]["bearing.n_balls"] == n_balls)
        peak[n_balls] = np.max(np.hypot(runs["libcosim"]["bearing.F_x"], runs["libcosim"]["bearing.F_y"]))
        for key in record:
            ref = runs["libcosim"][key]
            scale = np.max(np.abs(ref)) if key.endswith(("loaded_balls", "max_ball_load")) else peak[n_balls]
            assert np.max(np.abs(runs["ecos"][key] - ref)) <= 1e-10 * scale, key
            if key != "bearing.loaded_balls":
                # fmpy.ssp starts its connectors at 0, not at the start outputs (test_other_tools.py): ~1e-4
                assert np.max(np.abs(runs["fmpy"][key] - ref)) <= 1e-3 * scale, key
    assert abs(peak[15] - peak[8]) > 0.05 * peak[8]   # the 15-ball set is a different bearing


def test_run_parameter_set_picks_the_variant_ssd(ssp_archive):
    """`run --ssp FILE --parameter-set NAME`: our master reads the variant SSD of NAME."""
    config, system = ssp_config.config_from_ssp(ssp_archive, "BB1B420205-15balls-1200rpm")
    try:
        assert system.ssd == "BB1B420205-15balls-1200rpm.ssd"
        assert config.settings["n_balls"] == 15 and config.settings["allow_ball_overlap"] is True
    finally:
        system.close()
