"""How the reproduction's report writes its figures (mechanism/studies/reproduce/drawing.py, issue 11): drawn in
forked processes (the same bytes as drawn in-process), a child's error raised in the report, and a figure whose
inputs did not change (``inputs_key``) not drawn again."""
import os

import numpy as np
import pytest

from mechanism.cosim.record import RunResult
from mechanism.output.workers import ForkedSaves
from mechanism.studies.reproduce import drawing


def _figure(scale: float = 1.0):
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(4, 3))
    x = np.linspace(0.0, 4.0, 2001)
    ax.plot(x, scale * np.sin(7 * x), lw=0.7, label="run")
    ax.set_xlabel("crank angle [π rad]")
    ax.set_title("a figure")
    ax.legend()
    return fig


def _run(scale: float = 1.0) -> RunResult:
    t = np.linspace(0.0, 0.1, 101)
    return RunResult(["time", "F_x"], np.column_stack([t, scale * np.cos(t)]), {"config": {"rpm": 1200.0}})


def _in_a_fresh_process(body: str, tmp_path) -> None:
    """Run ``body`` (test code with ``tmp_path``) in a new interpreter: ``ForkedSaves`` forks only from a
    process with one thread, and the test session has others by now (tqdm's monitor, earlier tests' pools)."""
    import subprocess
    import sys
    import textwrap
    code = textwrap.dedent('''
        import os, pathlib
        import numpy as np
        import pytest
        from mechanism.output.workers import ForkedSaves
        from mechanism.studies.reproduce import drawing
        from tests.test_report_figures import _figure
        tmp_path = pathlib.Path(os.environ["FIGURE_TEST_DIR"])
    ''') + textwrap.dedent(body)
    env = dict(os.environ, FIGURE_TEST_DIR=str(tmp_path), MPLBACKEND="Agg")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr


def test_forked_figures_are_the_in_process_bytes(tmp_path):
    _in_a_fresh_process('''
        drawing.draw_figure(_figure(), tmp_path / "here.png")
        with ForkedSaves(2, drawing.draw_figure) as saves:
            assert saves.n == 2
            for k in range(3):
                saves.submit(_figure(), tmp_path / f"forked{k}.png")
        here = (tmp_path / "here.png").read_bytes()
        for k in range(3):
            assert (tmp_path / f"forked{k}.png").read_bytes() == here
    ''', tmp_path)


def test_a_child_error_is_raised_after_every_child_ended(tmp_path):
    _in_a_fresh_process('''
        def save(fig, path):
            if "bad" in path.name:
                raise ValueError("no such colour")
            drawing.draw_figure(fig, path)

        saves = ForkedSaves(2, save)
        assert saves.n == 2
        saves.submit(_figure(), tmp_path / "bad.png")
        saves.submit(_figure(), tmp_path / "good.png")
        with pytest.raises(RuntimeError, match="(?s)bad.png.*no such colour"):
            saves.wait()
        assert (tmp_path / "good.png").is_file() and not (tmp_path / "bad.png").exists()
        assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp.png")]
        saves.wait()   # nothing left: no error twice
    ''', tmp_path)


def test_no_fork_with_other_threads_or_n_zero(tmp_path):
    import threading
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()
    try:
        assert ForkedSaves(2, drawing.draw_figure).n == 0
    finally:
        stop.set()
        thread.join()
    saves = ForkedSaves(0, drawing.draw_figure)
    saves.submit(_figure(), tmp_path / "f.png")     # written at once, here
    assert (tmp_path / "f.png").is_file()


def test_the_inputs_key_covers_the_runs_samples_and_meta():
    key = drawing.inputs_key({"a": _run()}, "v1")
    assert key == drawing.inputs_key({"a": _run()}, "v1")
    changed_meta = _run()
    changed_meta.meta["config"]["rpm"] = 600.0
    for other in ({"a": _run(1.0 + 1e-15)}, {"b": _run()}, {"a": _run(), "b": _run()}, {"a": changed_meta}):
        assert drawing.inputs_key(other, "v1") != key
    assert drawing.inputs_key({"a": _run()}, "v2") != key


def test_figures_of_the_same_inputs_are_not_drawn_again(tmp_path):
    def draw_all(key: str, names=("f1.png", "f2.png")) -> drawing.FigureFiles:
        with drawing.FigureFiles(tmp_path, key, processes=1) as files:
            for name in names:
                drawing.save_figure(_figure(), tmp_path / name)
        return files

    files = draw_all("k1")
    assert files.drawn == ["f1.png", "f2.png"] and (tmp_path / drawing.KEY_FILE).read_text().strip() == "k1"
    before = {p.name: p.stat().st_mtime_ns for p in tmp_path.glob("*.png")}
    files = draw_all("k1")
    assert files.skipped == ["f1.png", "f2.png"] and not files.drawn
    assert before == {p.name: p.stat().st_mtime_ns for p in tmp_path.glob("*.png")}
    (tmp_path / "f2.png").unlink()              # a missing file is drawn again, the other is kept
    files = draw_all("k1")
    assert files.skipped == ["f1.png"] and files.drawn == ["f2.png"]
    files = draw_all("k2")                       # other inputs: every figure is drawn
    assert files.drawn == ["f1.png", "f2.png"] and (tmp_path / drawing.KEY_FILE).read_text().strip() == "k2"


def test_a_failed_drawing_leaves_no_key(tmp_path, monkeypatch):
    """The key stands only for a folder whose figures are complete: an error while drawing removes it."""
    with drawing.FigureFiles(tmp_path, "k1", processes=1):
        drawing.save_figure(_figure(), tmp_path / "f1.png")
    with pytest.raises(ZeroDivisionError), drawing.FigureFiles(tmp_path, "k2", processes=1):
        drawing.save_figure(_figure(), tmp_path / "f1.png")
        raise ZeroDivisionError
    assert not (tmp_path / drawing.KEY_FILE).exists()
    assert drawing._FILES is None                 # save_figure draws in-process again
