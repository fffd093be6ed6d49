"""The demo's outputs and the block diagram's skip path."""

import json
import shutil

import numpy as np
import pytest

from geovs_drake.loop import build_loop
from geovs_drake.plotting import write_block_diagram
from geovs_drake.scenario import Kinematic, ScenarioConfig

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


# The CLI's demo end to end with its rendered run: make test's budget; the in-process demo
# (test_demo_without_the_vision_extra...) stays.
@pytest.mark.slow
def test_demo_writes_every_result(tmp_path, run_cli):
    # 5 s: both runs converge by then (the rendered one at 1.7 mm, measured).
    out = run_cli("demo", "--out", str(tmp_path), "--duration", "5", subprocess=True)
    assert out.code == 0, out.err
    lines = out.out.strip().splitlines()
    assert lines[0].startswith("nf on the dynamic plant: converged")
    # Where the recording is: the saved file, not Drake's localhost URL (dead at exit).
    assert "localhost" not in out.out + out.err, out.err
    assert lines[1] == f"Meshcat recording: {(tmp_path / 'servo.html').resolve()} " + (
        "(open it in a web browser; it needs no server)"
    )
    # The same start through rendered frames (320x240, 30 Hz), beside it.
    assert lines[2].startswith(
        "rendered camera: nf on the dynamic plant, rendered camera 320x240 at 30 Hz: converged"
    )
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["converged"] and not summary["left_domain"] and summary["lyapunov_monotone"]
    rendered = json.loads((tmp_path / "rendered_summary.json").read_text())
    assert rendered["rendered"]["sensor"] == "rendered" and rendered["rendered"]["converged"]
    assert rendered["exact_same_gains"]["sensor"] == "exact"
    for name in (
        "image_view.png",
        "run.png",
        "nf_slices.png",
        "rendered_vs_exact.png",
        "camera_frames.png",
    ):
        assert (tmp_path / name).read_bytes()[:8] == PNG_MAGIC, name
    html = (tmp_path / "servo.html").read_text()
    assert "<html" in html.lower() and len(html) > 100_000  # the recording is embedded
    if shutil.which("dot"):
        assert "spherical_camera" in (tmp_path / "block_diagram.svg").read_text()


def test_block_diagram_is_skipped_with_a_message_without_dot(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    kinematic = build_loop(ScenarioConfig(plant=Kinematic()), log=False).diagram
    assert write_block_diagram(kinematic, tmp_path / "d") == []
    assert "skipping the block diagram" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


@pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz's dot is not installed")
def test_block_diagram_svg_names_the_systems(tmp_path):
    kinematic = build_loop(ScenarioConfig(plant=Kinematic()), log=False).diagram
    files = write_block_diagram(kinematic, tmp_path / "k")
    svg = files[0].read_text()
    for name in ("kinematic_rigid_body", "spherical_camera", "kinematic_controller"):
        assert name in svg


@pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz's dot is not installed")
def test_the_arm_s_block_diagram_top_to_bottom_fits_a_page_s_width(tmp_path):
    # Notebook 05's: left to right the arm's loop is five times wider than tall (4232 x
    # 805 px), unreadable at a page's width; top to bottom, its plant split, it is narrower
    # than tall. dot's own PNG header gives the sizes.
    from geovs_drake.scenario import Arm

    arm = build_loop(ScenarioConfig(carrier=Arm()), log=False).diagram

    def size(**kwargs) -> tuple[int, int]:
        png = write_block_diagram(arm, tmp_path / str(len(kwargs)), **kwargs)[1].read_bytes()
        return int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")

    wide, tall = size(), size(options={"plant/split": "I/O"}, rankdir="TB")
    assert wide[0] > 3 * wide[1]
    assert tall[0] < tall[1] and tall[0] < wide[0] / 3


def test_plots_label_what_they_show():
    """Distinct snapshot times in the image view's legend; labelled colour bars and an
    unclipped saddle star in the NF slices."""
    import matplotlib

    matplotlib.use("Agg")
    from geovs_drake.geometry.navigation import NavigationFunction
    from geovs_drake.plotting import plot_image_view, plot_navigation_slices
    from geovs_drake.scenario import ScenarioConfig
    from geovs_drake.simulation import simulate

    config = ScenarioConfig(duration=3.0)
    fig = plot_image_view(simulate(config))
    labels = [
        t.get_text() for t in fig.axes[0].get_legend().get_texts() if t.get_text()[:2] == "t "
    ]
    assert len(labels) == len(set(labels)) >= 5, labels
    nf = NavigationFunction(config.domain.to_domain(), config.goal_features())
    fig = plot_navigation_slices(nf)
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(bars) == 2 and all(ax.get_ylabel() == "phi" for ax in bars)
    stars = [
        line
        for ax in fig.axes
        for line in ax.get_lines()
        if line.get_marker() == "*" and 180 in line.get_ydata()
    ]
    assert stars and not stars[0].get_clip_on()


def test_meshcat_trail_has_beads_that_stay_visible():
    """WebGL draws lines 1 px wide: the trail also has spheres along it."""
    from pydrake.geometry import Meshcat

    from geovs_drake.visualization import draw_trail

    meshcat = Meshcat()
    X = np.tile(np.eye(4), (200, 1, 1))
    X[:, 0, 3] = np.linspace(0, 1, 200)
    draw_trail(meshcat, X, beads=20)
    assert meshcat.HasPath("/trail/line")
    assert all(meshcat.HasPath(f"/trail/bead_{k}") for k in range(20))
    assert not meshcat.HasPath("/trail/bead_20")


def _in_box(xy: np.ndarray, box) -> np.ndarray:
    return (xy[:, 0] > box.x0) & (xy[:, 0] < box.x1) & (xy[:, 1] > box.y0) & (xy[:, 1] < box.y1)


def _data_under_legends(fig) -> list[str]:
    """Labels of plotted lines and scatters with a point under some legend of ``fig``
    (lines sampled densely along their segments, in display coordinates)."""
    fig.canvas.draw()
    hidden = []
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is None:
            continue
        box = legend.get_window_extent()
        clip = ax.get_window_extent()
        for artist in [*ax.get_lines(), *ax.collections]:
            if hasattr(artist, "get_xydata"):
                xy = artist.get_transform().transform(artist.get_xydata())
                t = np.linspace(0, 1, 50)[:, None]
                pairs = zip(xy[:-1], xy[1:], strict=True)
                xy = np.concatenate([a + t * (b - a) for a, b in pairs] or [xy])
            else:
                xy = artist.get_offset_transform().transform(artist.get_offsets())
            inside = _in_box(xy, clip) & _in_box(xy, box)
            if np.any(inside):
                hidden.append(f"{ax.get_title()}: {artist.get_label()}")
    return hidden


def test_legends_hide_no_data():
    """A legend over the data hides it: the FOV boundary under the image view's legend,
    the saddle's line under the circle slice's. Every legend sits clear of every curve."""
    import matplotlib

    matplotlib.use("Agg")
    from geovs_drake.geometry.navigation import NavigationFunction
    from geovs_drake.plotting import plot_image_view, plot_navigation_slices, plot_run
    from geovs_drake.scenario import ScenarioConfig
    from geovs_drake.simulation import simulate

    config = ScenarioConfig(duration=3.0)
    result = simulate(config)
    nf = NavigationFunction(config.domain.to_domain(), config.goal_features())
    for fig in (plot_image_view(result), plot_run(result), plot_navigation_slices(nf)):
        assert _data_under_legends(fig) == []


def test_demo_without_the_vision_extra_skips_the_rendered_run_and_says_so(
    tmp_path, monkeypatch, capsys
):
    """A plain install has no OpenCV: the demo runs, a note on stderr names the extra,
    and no rendered file is written."""
    import geovs_drake.demo as demo
    from geovs_drake._optional import MissingExtra

    def missing(module, extra, needed_by, package=None):
        raise MissingExtra(package or module, extra, needed_by)

    monkeypatch.setattr(demo, "require", missing)
    result = demo.run_demo(tmp_path, duration=0.5, meshcat=False, rendered=True)
    err = capsys.readouterr().err
    assert result.sim_time_s == pytest.approx(0.5)
    assert (
        "skipping the rendered run: the demo's rendered run needs opencv-python-headless: "
        'pip install "geovs-drake[vision]"'
    ) in err
    assert (tmp_path / "summary.json").is_file()
    assert not (tmp_path / "rendered_vs_exact.png").exists()


@pytest.mark.slow  # 8 s (the arm's meshes in Meshcat): make test's budget; the demo's test stays
def test_demo_on_the_arm_records_the_arm_servoing(tmp_path, run_cli):
    """`demo --carrier arm`: the same hard start, IK to the arm's joints, the Meshcat
    recording of the arm (the rendered run left out here: the arm's camera loops are held
    in test_arm.py)."""
    out = run_cli(
        "demo", "--carrier", "arm", "--out", str(tmp_path), "--duration", "8", "--no-rendered",
        subprocess=True,
    )  # fmt: skip
    assert out.code == 0, out.err
    assert out.out.startswith("nf on the dynamic plant: converged"), out.out
    assert "skipping" not in out.err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["carrier"] == "arm" and summary["lyapunov_monotone"]
    assert summary["min_joint_limit_margin"] > 0
    html = (tmp_path / "servo.html").read_text()
    assert "<html" in html.lower() and len(html) > 1_000_000  # the arm's meshes, animated
    assert not (tmp_path / "rendered_summary.json").exists()
    if shutil.which("dot"):
        assert "arm_camera" in (tmp_path / "block_diagram.svg").read_text()


@pytest.mark.slow
def test_the_rendered_demo_on_the_arm_draws_the_arms_camera_frames(tmp_path):
    """The demo's rendered part on the arm (it was skipped there): the frames are the
    arm's camera's, at the run's own joint states (a free body's state would not fit the
    arm's plant)."""
    pytest.importorskip("cv2")
    from geovs_drake.demo import demo_config, run_rendered_demo
    from geovs_drake.scenario import Arm

    run = run_rendered_demo(demo_config(1.0, Arm()), tmp_path)
    assert run.summary()["carrier"] == "arm" and run.summary()["sensor"] == "rendered"
    assert (tmp_path / "camera_frames.png").stat().st_size > 0
    summary = json.loads((tmp_path / "rendered_summary.json").read_text())
    assert summary["exact_same_gains"]["carrier"] == "arm"
