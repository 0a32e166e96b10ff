"""The run plots read as the issue asks: one panel per actual ball, the steady revolution on its own scale
beside a start-up panel, titles with speed, ball count, damping and clearance."""
import numpy as np
import pytest

from mechanism.cosim.record import RunResult
from mechanism.output import plots


def fake_run(balls: int, capacity: int = 20, revs: float = 2.0) -> RunResult:
    """Two revolutions at 1200 rpm with a start-up spike 100x the steady force, and `capacity` ball columns."""
    t = np.linspace(0.0, revs * 0.05, 2001)
    angle = 2 * np.pi * t / 0.05
    force = 100 * np.cos(angle) + np.where(t < 0.002, 1e4, 0.0)
    cols = {"time": t, "crank_angle": angle, "e_x": 1e-5 * np.cos(angle), "e_y": 1e-5 * np.sin(angle),
            "F_x": force, "F_y": force / 2, "slider_x": 0.1 + 0 * t, "slider_a": force, "crank_moment": force / 10}
    for k in range(1, capacity + 1):
        cols[f"ball_load_{k}"] = np.maximum(0.0, np.cos(angle - k)) * 50 if k <= balls else 0 * t
    meta = {"config": {"rpm": 1200.0, "joint": "bearing", "balls": balls, "settings": {"damping_coefficient": 80.0}},
            "clearance_per_side_m": 1e-5}
    return RunResult(list(cols), np.column_stack(list(cols.values())), meta)


def test_plots_one_panel_per_ball_steady_scale_and_full_titles(tmp_path, monkeypatch):
    saved = {}

    def keep(fig, path):
        saved[path.name] = ([ax for ax in fig.axes if ax.get_visible()], fig._suptitle.get_text()
                            if fig._suptitle else fig.axes[0].get_title())
        fig.savefig(path, dpi=30)
        return path

    monkeypatch.setattr(plots, "_save", keep)
    plots.plot_run(fake_run(8), tmp_path)
    axes, _ = saved["ball_loads.png"]
    assert len(axes) == 8
    for name in ("ball_loads.png", "joint_force.png", "slider_acceleration.png", "eccentricity.png"):
        text = saved[name][1]
        assert "1200 rpm" in text and "8 balls" in text and "C = 80 N·s/m" in text and "P_d = 20 µm" in text, text
    # the steady panel's scale is the steady force's (100 N), not the start-up spike's (1e4 N)
    axes, _ = saved["slider_acceleration.png"]
    start, steady = axes
    assert steady.get_ylim()[1] < 200 and start.get_ylim()[1] > 5e3
    assert "revolution 2" in steady.get_title()
    plots.plot_run(fake_run(15), tmp_path)
    assert len(saved["ball_loads.png"][0]) == 15


def test_windows_for_short_runs_use_the_second_half():
    x = np.linspace(0, 1.0, 101)   # half a revolution, in π rad
    start, steady, name = plots.windows(x)
    assert name == "second half of the run" and steady.sum() == 51 and start[0] and not start[-1]


def test_envelope_keeps_every_peak_in_order_with_few_points():
    """The min/max envelope draws a long curve with about MAX_POINTS points and keeps its extremes (so the axes
    autoscale as with every sample), the first and the last sample, in time order."""
    rng = np.random.default_rng(3)
    for n in (50, 4001, 100_001):
        y, x = rng.normal(size=n), rng.normal(size=n)
        y[n // 3], x[n // 2] = 40.0, -30.0
        for curves in ((y,), (x, y)):
            k = plots.envelope(*curves)
            assert len(k) <= max(n, 1) and len(k) <= plots.MAX_POINTS + 20
            assert k[0] == 0 and k[-1] == n - 1 and np.all(np.diff(k) > 0)
            for c in curves:
                assert c[k].max() == c.max() and c[k].min() == c.min()
    assert len(plots.envelope(np.arange(10.0))) == 10


def test_a_figure_is_written_whole_or_not_at_all(tmp_path):
    """PNGs are written to a temporary name and renamed (issue 14): a failing savefig leaves the old file as it
    was and no temporary behind; a good one replaces it."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mechanism.output.atomic import save_figure
    path = tmp_path / "f.png"
    path.write_bytes(b"old")
    fig = plt.figure()

    def broken(target, **kwargs):
        with open(target, "wb") as f:
            f.write(b"\x89PNG half")
        raise OSError(28, "No space left on device")

    good = fig.savefig
    fig.savefig = broken
    with pytest.raises(OSError):
        save_figure(fig, path, dpi=50)
    assert path.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["f.png"]
    fig.savefig = good
    save_figure(fig, path, dpi=50)
    plt.close(fig)
    assert path.read_bytes()[:4] == b"\x89PNG" and sorted(p.name for p in tmp_path.iterdir()) == ["f.png"]


def test_prepared_frames_draw_the_bytes_of_frames_built_with_the_data(tmp_path):
    """A figure drawn over a frame prepared before the data (``plots.prepare``: the output workers do it while the
    run runs) is the file drawn without one; a frame prepared for another end of the run (its background drawn
    for other x limits and titles) is drawn again, to the same bytes."""
    from mechanism.output.figures import Plan
    r = fake_run(8)
    angle = r["crank_angle"]
    energy = {"damping_dissipation": 1e-3 * angle, "contact_energy": 1e-4 * np.sin(angle) ** 2,
              "cage_work": -1e-5 * angle, "energy_residual": 1e-7 * np.cos(3 * angle)}
    r = RunResult(r.columns + list(energy), np.column_stack([r.data, *energy.values()]), r.meta)
    ideal = RunResult(r.columns, r.data.copy(), r.meta)
    ideal.data[:, ideal.columns.index("slider_x")] += 1e-6
    (tmp_path / "here").mkdir()
    here = plots.plot_run(r, tmp_path / "here", ideal)
    assert [p.name for p in here] == list(plots.FIGURES)
    for end in (4.0, 3.0):
        frames = plots.prepare(Plan(r.meta, True, end), plots.FIGURES)
        assert sorted(frames) == sorted(plots.FIGURES)
        (tmp_path / f"{end}").mkdir()
        there = plots.plot_run(r, tmp_path / f"{end}", ideal, frames=frames)
        assert not frames     # every frame was used
        for a, b in zip(here, there):
            assert a.read_bytes() == b.read_bytes(), (end, a.name)


def test_a_frame_for_another_run_is_not_used(tmp_path):
    """A prepared frame whose run differs from the data's (another ball count here) is built again."""
    from mechanism.output.figures import Plan
    r = fake_run(8)
    frames = plots.prepare(Plan({**r.meta, "config": {**r.meta["config"], "balls": 12}}, False, 4.0),
                           ("ball_loads.png",))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    [drawn] = plots.plot_run(r, tmp_path / "a", None, names=("ball_loads.png",), frames=frames)
    assert drawn.read_bytes() == plots.plot_run(r, tmp_path / "b", None, names=("ball_loads.png",))[0].read_bytes()


def test_the_png_writer_gives_the_canvas_pixels(tmp_path):
    """``atomic.png_bytes`` held against Pillow's PNG decoder: the pixels, the resolution and matplotlib's
    Software text of the canvas a figure was drawn into."""
    from PIL import Image

    from mechanism.output.atomic import save_canvas
    fig = plots._figure((3, 2))
    ax = fig.subplots()
    ax.plot([0, 1, 2], [1, -1, 0.5], lw=2)
    ax.set_title("pixels", y=plots.TITLE_Y)
    fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba()).copy()
    save_canvas(fig.canvas, tmp_path / "f.png")
    with Image.open(tmp_path / "f.png") as im:
        assert im.mode == "RGBA" and np.array_equal(np.asarray(im), rgba)
        assert np.allclose(im.info["dpi"], plots.DPI, atol=0.01) and im.info["Software"].startswith("Matplotlib")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.png"]


def test_an_ideal_run_without_the_column_leaves_the_run_curve_in_its_own_style(tmp_path):
    """With an ideal counterpart that lacks a plotted column, the run's curve is drawn as the run's (the last
    curves of the row), not in the ideal's style (a reviewer's finding: the curves were paired from the front)."""
    from mechanism.cosim.record import RunResult
    n = 2001
    t = np.linspace(0.0, 0.1, n)
    crank = 2 * np.pi * 20 * t
    cols = ["time", "crank_angle", "slider_a"]
    r = RunResult(cols, np.column_stack([t, crank, np.sin(crank)]), {"crank_period_s": 0.05})
    ideal = RunResult(cols[:2], np.column_stack([t, crank]), {})
    frame = plots.build("slider_acceleration.png", r.meta, True)
    plots._fill_time(frame, r, ideal, plots.crank_pi(r))
    (ideal_start, ideal_steady), (run_start, run_steady) = frame.lines[0]
    assert len(ideal_start.get_xdata()) == len(ideal_steady.get_xdata()) == 0
    assert len(run_start.get_xdata()) + len(run_steady.get_xdata()) > 0


def test_the_png_writer_refuses_what_is_not_8_bit_rgba():
    from mechanism.output.atomic import png_bytes
    with pytest.raises(ValueError, match="8-bit RGBA"):
        png_bytes(np.zeros((2, 2, 4)), 100.0)
    with pytest.raises(ValueError, match="8-bit RGBA"):
        png_bytes(np.zeros((2, 2, 3), np.uint8), 100.0)
