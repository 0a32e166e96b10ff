"""numba's cache folder is keyed by every compiled source (mechanism/kernel_cache.py): numba itself checks only a
function's own file, so an edit of a callee in another module would otherwise load stale machine code."""
import shutil

from mechanism import kernel_cache


def _copy(tmp_path):
    for rel in ("cosim/law_kernel.py", "cosim/compiled_loop.py", "run.py"):
        target = tmp_path / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(kernel_cache.PACKAGE / rel, target)
    return tmp_path


def test_the_key_follows_every_compiled_source_and_only_those(tmp_path, monkeypatch):
    monkeypatch.setattr(kernel_cache, "PACKAGE", _copy(tmp_path))
    assert [p.name for p in kernel_cache.sources()] == ["compiled_loop.py", "law_kernel.py"]
    before = kernel_cache.key()
    law = tmp_path / "cosim" / "law_kernel.py"
    law.write_text(law.read_text() + "\n# an edit of the callee only\n")
    edited = kernel_cache.key()
    assert edited != before                     # run_steps' cache is left behind with its old callee
    (tmp_path / "run.py").write_text("# not compiled\n")
    assert kernel_cache.key() == edited


def test_the_folder_under_the_users_cache_dir_and_inherited_unchanged(tmp_path):
    name = kernel_cache.PREFIX + kernel_cache.key()
    assert kernel_cache.folder({}) == kernel_cache.PACKAGE / "__pycache__" / "numba" / name
    given = kernel_cache.folder({"NUMBA_CACHE_DIR": str(tmp_path)})
    assert given == tmp_path / name
    assert kernel_cache.folder({"NUMBA_CACHE_DIR": str(given)}) == given      # a child process's environment
    # a child of other sources (an older key in the inherited name): a sibling for its own key, not a folder inside
    older = tmp_path / (kernel_cache.PREFIX + "0123456789abcdef")
    assert kernel_cache.folder({"NUMBA_CACHE_DIR": str(older)}) == given
    # a folder of the user's own that only starts like ours is the user's base, as any other
    own = tmp_path / (kernel_cache.PREFIX + "cache")
    assert kernel_cache.folder({"NUMBA_CACHE_DIR": str(own)}) == own / name


def test_numba_uses_the_folder():
    """In a fresh process (not this one, whose numba config other tests' processes may have changed), importing
    mechanism points numba at the folder keyed by the current sources, and a kernel's cache lives there."""
    import os
    import subprocess
    import sys
    code = ("import os, numba; from mechanism import kernel_cache; from mechanism.cosim import law_kernel; "
            "print(numba.config.CACHE_DIR); print(os.environ['NUMBA_CACHE_DIR']); "
            "print(kernel_cache.PREFIX + kernel_cache.key()); print(law_kernel.evaluate._cache._cache_path)")
    root = kernel_cache.PACKAGE.parent
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(root)
    config, environ, name, path = subprocess.run([sys.executable, "-c", code], env=env, cwd=root, check=True,
                                                 capture_output=True, text=True).stdout.split("\n")[:4]
    assert config == environ and os.path.basename(config) == name
    assert config == str(kernel_cache.PACKAGE / "__pycache__" / "numba" / name)
    assert path.startswith(config)


def test_the_key_follows_the_modules_a_kernel_takes_constants_from(tmp_path, monkeypatch):
    """numba folds a kernel's globals into its machine code, so the key covers the modules the compiled ones import
    (through each other too: fmu_bearing.parameters' own import here), and an edit of one starts a fresh cache; a
    module no kernel reaches does not."""
    pkg, fb = tmp_path / "mechanism", tmp_path / "fmu_bearing"
    (pkg / "cosim").mkdir(parents=True)
    fb.mkdir()
    (pkg / "cosim" / "law_kernel.py").write_text(
        "from numba import njit\n\nfrom fmu_bearing.parameters import (\n    DAMPING_CONSTANT,\n)\n"
        "from mechanism.cosim.joint import LINK\n")
    (pkg / "cosim" / "joint.py").write_text("LINK = 1\n")
    (fb / "__init__.py").write_text("")
    (fb / "parameters.py").write_text("def _units():\n    from . import units  # in a function, relative\n"
                                      "    return units\n\n\nDAMPING_CONSTANT = 1\n")
    (fb / "units.py").write_text("MM = 1e-3\n")
    (fb / "slave.py").write_text("# no kernel imports this\n")
    monkeypatch.setattr(kernel_cache, "PACKAGE", pkg)
    assert [p.relative_to(tmp_path).as_posix() for p in kernel_cache.dependencies()] == [
        "fmu_bearing/__init__.py", "fmu_bearing/parameters.py", "fmu_bearing/units.py", "mechanism/cosim/joint.py"]
    before = kernel_cache.key()
    (fb / "slave.py").write_text("# edited\n")
    assert kernel_cache.key() == before
    for edited in (fb / "units.py", fb / "parameters.py", pkg / "cosim" / "joint.py"):
        edited.write_text(edited.read_text() + "# edited\n")
        assert kernel_cache.key() != before, edited.name
        before = kernel_cache.key()


def test_the_real_kernels_dependencies():
    """The constants' modules the kernels use today are in the key: the damping model's codes, the life's exponents
    (and a module imported after a one-line import, which a greedy pattern once swallowed, and one imported
    relatively)."""
    names = {p.relative_to(kernel_cache.PACKAGE.parent).as_posix() for p in kernel_cache.dependencies()}
    assert {"fmu_bearing/parameters.py", "fmu_bearing/life.py", "fmu_bearing/ball_bearing.py",
            "fmu_bearing/hertz.py", "mechanism/cosim/joint.py"} <= names     # hertz: ball_bearing's `from . import`
    assert not names & {p.relative_to(kernel_cache.PACKAGE.parent).as_posix() for p in kernel_cache.sources()}
