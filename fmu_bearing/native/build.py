"""Compile the FMU loader (``loader.c``) with zig's C compiler and put it into a pythonfmu FMU.

``build_loader(fmu)`` rewrites a pythonfmu FMU in place:

* ``binaries/linux64/<id>.so`` (pythonfmu's binary) becomes ``binaries/linux64/<id>_pythonfmu.so`` and the
  loader, compiled for x86_64 Linux with glibc 2.17 symbol versions, becomes ``binaries/linux64/<id>.so``;
  the same for ``binaries/win64`` (cross-compiled, x86_64-windows-gnu) when the FMU has a Windows binary.
  macOS is not built: pythonfmu 0.7 ships no macOS binary to forward to.
* when the FMU has outputs holding the tangent matrices (``stiffness_ij = dF_i/de_j``,
  ``damping_ij = dF_i/dv_j``, docs/fmu-interface.md), the loader is compiled with a table of them and
  implements ``fmi2GetDirectionalDerivative``; the model description then declares
  ``providesDirectionalDerivative="true"``.

The compiler is ``python -m ziglang cc`` (the ``ziglang`` package from PyPI): the same compiler on any
build machine, which also cross-compiles. Build-time only: nothing here runs inside the FMU.
"""
from __future__ import annotations

import os
import re
import shutil
import stat
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "loader.c"
#: FMI platform folder -> (zig target, library suffix)
TARGETS = {
    "linux64": ("x86_64-linux-gnu.2.17", ".so"),
    "win64": ("x86_64-windows-gnu", ".dll"),
}
#: (output, input) -> output holding d output / d input (the joint-component coupling outputs)
PARTIALS = {
    ("F_x", "e_x"): "stiffness_xx", ("F_x", "e_y"): "stiffness_xy",
    ("F_y", "e_x"): "stiffness_xy", ("F_y", "e_y"): "stiffness_yy",
    ("F_x", "v_x"): "damping_xx", ("F_x", "v_y"): "damping_xy",
    ("F_y", "v_x"): "damping_xy", ("F_y", "v_y"): "damping_yy",
}
PYTHONFMU_SUFFIX = "_pythonfmu"


class LoaderBuildError(RuntimeError):
    """The loader could not be compiled (no zig, or a compiler error)."""


def zig_cc() -> list[str]:
    """The command of zig's C compiler, from the ``ziglang`` package of this Python."""
    try:
        import ziglang  # noqa: F401
    except ImportError as err:
        raise LoaderBuildError("the FMU loader needs the C compiler of the 'ziglang' package: "
                               "pip install ziglang") from err
    return [sys.executable, "-m", "ziglang", "cc"]


def derivative_table(model_description: bytes) -> list[tuple[int, int, int]]:
    """Rows (unknown vr, known vr, source vr) of ``PARTIALS`` whose three variables the FMU has."""
    root = ElementTree.fromstring(model_description)
    vr = {v.get("name"): int(v.get("valueReference")) for v in root.iter("ScalarVariable")}
    return [(vr[out], vr[inp], vr[src]) for (out, inp), src in PARTIALS.items()
            if out in vr and inp in vr and src in vr]


def compile_loader(platform: str, output: Path, table: list[tuple[int, int, int]] = ()) -> Path:
    """Compile ``loader.c`` for an FMI ``platform`` (a key of ``TARGETS``) into ``output``."""
    target, _ = TARGETS[platform]
    with tempfile.TemporaryDirectory(prefix="fmu_loader_") as tmp:
        config = Path(tmp) / "loader_config.h"
        rows = ", ".join("{%d, %d, %d}" % row for row in table)
        config.write_text(f"#define DD_COUNT {len(table)}\n"
                          + (f"#define DD_TABLE {{{rows}}}\n" if table else ""), encoding="utf-8")
        command = [*zig_cc(), "-target", target, "-shared", "-O2", "-std=c99", "-Wall", "-Werror",
                   "-ffp-contract=off", "-fno-fast-math",   # the C step's doubles = Python's (loader.c, "C step")
                   f'-DLOADER_CONFIG="{config.as_posix()}"', "-o", str(output), str(SOURCE)]
        if platform == "linux64":
            # -Bsymbolic: the loader's own calls of its exported functions bind to them, never to a same-named
            # global symbol of another library (another FMU, the host) loaded before it
            command[4:4] = ["-fPIC", "-fvisibility=hidden", "-Wl,-Bsymbolic", "-s"]
            command.append("-ldl")
            command.append("-lpthread")
        else:
            command[4:4] = ["-s"]
        proc = subprocess.run(command, capture_output=True, text=True, cwd=tmp)
        if proc.returncode != 0:
            raise LoaderBuildError(f"compiling the {platform} loader failed:\n{' '.join(command)}\n{proc.stderr}")
        for junk in (output.with_suffix(".lib"), output.with_suffix(".pdb")):
            if junk.exists():
                junk.unlink()
    return output


def glibc_requirement(library: Path) -> str | None:
    """Highest GLIBC_x.y symbol version ``library`` needs (objdump -T), or None without objdump."""
    objdump = shutil.which("objdump")
    if objdump is None:
        return None
    text = subprocess.run([objdump, "-T", str(library)], capture_output=True, text=True).stdout
    versions = {tuple(int(p) for p in m.split(".")) for m in re.findall(r"GLIBC_(\d+(?:\.\d+)+)", text)}
    return "GLIBC_" + ".".join(map(str, max(versions))) if versions else "none"


def build_loader(fmu: str | Path, platforms: tuple[str, ...] = tuple(TARGETS)) -> dict[str, Path]:
    """Put the loader into the pythonfmu FMU ``fmu`` (rewritten in place); return {platform: path in zip}.

    Only the platforms of ``platforms`` for which the FMU has a pythonfmu binary get a loader.
    """
    fmu = Path(fmu)
    with zipfile.ZipFile(fmu) as z:
        entries = {info.filename: (info, z.read(info)) for info in z.infolist()}
    md = entries["modelDescription.xml"][1]
    root = ElementTree.fromstring(md)
    cs = root.find("CoSimulation")
    model_id = cs.get("modelIdentifier")
    table = derivative_table(md)
    built: dict[str, Path] = {}
    with tempfile.TemporaryDirectory(prefix="fmu_loader_") as tmp:
        for platform in platforms:
            _, suffix = TARGETS[platform]
            original = f"binaries/{platform}/{model_id}{suffix}"
            if original not in entries:
                continue
            if f"binaries/{platform}/{model_id}{PYTHONFMU_SUFFIX}{suffix}" in entries:
                raise ValueError(f"{fmu} already has a loader for {platform}")
            loader = compile_loader(platform, Path(tmp) / f"{platform}{suffix}", table)
            info, data = entries.pop(original)
            entries[f"binaries/{platform}/{model_id}{PYTHONFMU_SUFFIX}{suffix}"] = (info, data)
            entries[original] = (info, loader.read_bytes())
            built[platform] = Path(original)
        if table and "linux64" in built:
            entries["modelDescription.xml"] = (entries["modelDescription.xml"][0],
                                               _declare_directional_derivative(md))
        tmp_fmu = fmu.with_name(f".{fmu.name}.{os.getpid()}.loader")
        with zipfile.ZipFile(tmp_fmu, "w", zipfile.ZIP_DEFLATED) as z:
            for name, (info, data) in entries.items():
                entry = zipfile.ZipInfo(name, info.date_time)
                # regular files readable by all (rw-r--r--), libraries rwxr-xr-x
                mode = 0o755 if name.startswith("binaries/") else 0o644
                entry.external_attr = (stat.S_IFREG | mode) << 16
                z.writestr(entry, data, zipfile.ZIP_DEFLATED)
        os.replace(tmp_fmu, fmu)
    return built


def _declare_directional_derivative(md: bytes) -> bytes:
    """The model description with providesDirectionalDerivative="true" on <CoSimulation> (text edit:
    the rest of the file stays byte for byte as pythonfmu wrote it)."""
    text = md.decode("utf-8")
    match = re.search(r"<CoSimulation\b[^>]*?(/?>)", text)
    if match is None:
        raise ValueError("modelDescription.xml has no <CoSimulation> element")
    element = match.group(0)
    if "providesDirectionalDerivative" in element:
        element = re.sub(r'providesDirectionalDerivative="[^"]*"', 'providesDirectionalDerivative="true"', element)
    else:
        close = match.group(1)
        element = element[: -len(close)].rstrip() + ' providesDirectionalDerivative="true"' + close
    return (text[: match.start()] + element + text[match.end():]).encode("utf-8")


def main(argv: list[str] | None = None) -> int:
    """``python -m fmu_bearing.native.build FMU...``: add the loader to already built pythonfmu FMUs."""
    import argparse
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("fmus", nargs="+")
    args = parser.parse_args(argv)
    for path in args.fmus:
        built = build_loader(path)
        print(f"{path}: loader for {', '.join(built) or 'no platform'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
