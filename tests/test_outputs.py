"""Outputs land where users look: beside the input or in a printed directory, never among
tracked files; progress bars (with an ETA) only on a terminal."""
import io
import fcntl
import os
import select
import shutil
import struct
import subprocess
import termios
from pathlib import Path

import pytest

from hexapod_bringup.cmd_analyze import beside, default_out
from hexapod_bringup.cmd_experiments import progress_factory

ROOT = Path(__file__).resolve().parents[1]


def _terminal():
    """A pseudo-terminal 120 columns wide: (master fd, slave fd)."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 120, 0, 0))
    return master, slave


def _drain(fd):
    """Everything written to a pty so far (its reads come in pieces)."""
    chunks = []
    while select.select([fd], [], [], 0.2)[0]:
        chunks.append(os.read(fd, 65536))
    return b"".join(chunks).decode()


def test_beside_names_the_output_after_the_bag_in_its_directory(tmp_path, monkeypatch):
    assert beside("bags/run1", "_analysis") == Path("bags/run1_analysis")
    assert beside("bags/run1/", ".gif") == Path("bags/run1.gif")
    assert beside("/data/x.mcap", "_analysis") == Path("/data/x_analysis")
    monkeypatch.chdir(tmp_path)
    assert beside(".", "_analysis") == tmp_path.with_name(tmp_path.name + "_analysis")
    assert default_out(["a/r1"]) == Path("a/r1_analysis")
    assert default_out(["a/r1", "b/r2.mcap"]) == Path("a/r1+r2_analysis")
    many = [f"a/{'long_bag_name_' * 2}{k}" for k in range(5)]
    assert default_out(many) == Path(f"a/{'long_bag_name_' * 2}0+4_more_analysis")


def test_no_generated_figure_is_tracked_outside_report():
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: nothing tracked to check")
    tracked = subprocess.run(["git", "ls-files", "*.png", "*.gif", "*.mp4", "*.svg"],
                             cwd=ROOT, capture_output=True, text=True, check=True).stdout
    outside = [f for f in tracked.split() if not f.startswith("report/")]
    assert outside == []


def test_progress_bar_with_eta_on_a_terminal_and_silent_otherwise():
    master, slave = _terminal()
    with os.fdopen(slave, "w") as tty:
        update = progress_factory(True, tty)("sweep", 4)
        update(1)
        update(3)
        tty.flush()
        shown = _drain(master)
    os.close(master)
    assert "sweep" in shown and "ETA" in shown and "4/4" in shown
    master, slave = os.openpty()  # a terminal that reports no size: a bar all the same
    with os.fdopen(slave, "w") as tty:
        progress_factory(True, tty)("sweep", 2)(2)
        tty.flush()
        shown = _drain(master)
    os.close(master)
    assert "sweep: 100%" in shown and "ETA" in shown and "2/2" in shown
    pipe = io.StringIO()
    update = progress_factory(True, pipe)("sweep", 4)
    update(4)
    assert pipe.getvalue() == ""
    master, slave = _terminal()
    with os.fdopen(slave, "w") as tty:
        progress_factory(False, tty)("sweep", 4)(4)
        tty.write("x")
        tty.flush()
        assert _drain(master) == "x"
    os.close(master)


def test_report_figures_are_drawn_on_the_workers_and_their_failures_raised(tmp_path):
    """reproduce draws its figures on the local workers between their runs (plots.Drawer):
    the file is there once wait() returns, and a figure that fails raises there; without
    local workers (inline) a figure is drawn at once."""
    import numpy as np

    from hexapod_bringup import plots
    from hexapod_bringup.core.parallel import InlineBackend, MemoBackend, ProcessBackend

    series = {"pd_p": (np.linspace(0.0, 1.0, 50), np.linspace(0.0, 2.0, 50))}
    with ProcessBackend(2) as pool:
        drawer = plots.Drawer(MemoBackend(pool))
        drawer.draw(plots.time_plot, series, "dxH", tmp_path / "worker.png", "on a worker")
        drawer.wait()
        assert (tmp_path / "worker.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        drawer.draw(plots.time_plot, series, "no such signal", tmp_path / "bad.png", "")
        with pytest.raises(KeyError, match="no such signal"):
            drawer.wait()
    here = plots.Drawer(InlineBackend())
    here.draw(plots.time_plot, series, "dyH", tmp_path / "here.png", "here")
    assert (tmp_path / "here.png").exists()


def _sweep_curves(seed, checked, names, scale):
    """Made-up sweep curves of two controllers over 40 values: a diverged point, unconverged
    points and a band, ``scale`` times values of order 1-100."""
    import numpy as np

    from hexapod_bringup import plots

    rng = np.random.default_rng(seed)
    curves = {}
    for c in ("pd_p", "pd_pf"):
        for n in names:
            y = scale * rng.uniform(1.0, 100.0, 40)
            y[7] = np.nan
            ok = rng.random(40) > 0.2
            curves[(c, n)] = (y, ok & ~np.isnan(y), 0.95 * y, 1.05 * y)
    return plots.SweepCurves(np.geomspace(0.1, 10.0, 40), checked, curves)


@pytest.mark.parametrize("names", [("E_av",), ("E_av", "F_L")])
def test_a_reused_sweep_canvas_draws_the_same_pixels_as_a_new_one(tmp_path, names):
    """sweep_plot clears and reuses one figure per layout (its tick objects are most of a
    figure's time): a figure drawn on a canvas that held another one, checked or not and on
    another scale, is pixel for pixel the figure drawn on a new canvas."""
    from matplotlib.image import imread

    from hexapod_bringup import plots

    pairs = [(_sweep_curves(1, True, names, 1.0), _sweep_curves(2, False, names, 1e3)),
             (_sweep_curves(3, False, names, 1e3), _sweep_curves(4, True, names, 1.0))]
    for k, (before, after) in enumerate(pairs):
        plots._SWEEP_CANVASES.clear()
        plots.sweep_plot(before, names, tmp_path / f"before{k}.png", "before")
        canvas = next(iter(plots._SWEEP_CANVASES.values()))
        plots.sweep_plot(after, names, tmp_path / f"reused{k}.png", "after")
        assert next(iter(plots._SWEEP_CANVASES.values())) is canvas  # reused, not made anew
        plots._SWEEP_CANVASES.clear()
        plots.sweep_plot(after, names, tmp_path / f"new{k}.png", "after")
        reused, new = imread(tmp_path / f"reused{k}.png"), imread(tmp_path / f"new{k}.png")
        assert reused.shape == new.shape
        assert (reused == new).all(), f"pair {k}: {(reused != new).any(axis=-1).sum()} pixels"
        before = imread(tmp_path / f"before{k}.png")
        assert before.shape != new.shape or (before != new).any()  # the test sees a change
