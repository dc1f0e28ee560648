"""Offline analysis: equals the engine, splits at switches, survives hundreds of bad bags."""
import signal
from pathlib import Path

import numpy as np
import pytest

from hexapod_control.core.closed_loop import run
from hexapod_metrics.core.analysis import analyze_bag
from hexapod_metrics.bag import BagWriter
from hexapod_metrics.bag import BagReadError
from hexapod_metrics.core.indices import INDEX_NAMES
from hexapod_metrics.core.recording import write_run_bag
from hexapod_bringup.core.simulate import simulate
from hexapod_common.core.params import load_params

#: One worker runs the module (its module-scoped fixture once): scripts/test.sh uses
#: pytest-xdist's loadgroup distribution.
pytestmark = pytest.mark.xdist_group("test_analysis")

#: analysis behaviour, not the paper's numbers: model.md's 1e-4 s physics, 1 kHz control
FAST = {"sim.dt": 1e-4, "sim.control_period": 1e-3}


@pytest.fixture(scope="module")
def switched_bag(tmp_path_factory):
    p = load_params(**FAST)
    r = run(p, "pd_pf", 4.0, switches=[(2.0, "pd_p")])
    return write_run_bag(r, tmp_path_factory.mktemp("bags") / "switched"), r


def test_analysis_equals_engine_and_online_indices(tmp_path):
    p = load_params(**FAST)
    sim = simulate(p, "pd_pf")
    bag = write_run_bag(sim.run, tmp_path / "bag")
    a = analyze_bag(bag)
    assert not a.truncated and a.ticks == 3001 and len(a.cycles) == 3
    last = a.cycles[-1].indices
    for name in INDEX_NAMES + ("L",):
        assert getattr(last, name) == pytest.approx(getattr(sim.indices, name), rel=1e-12)
    online = {c: idx for c, _, idx in a.online}
    for c in a.cycles:
        for name in INDEX_NAMES:
            assert getattr(online[c.cycle], name) == pytest.approx(getattr(c.indices, name),
                                                                   rel=1e-12)


def test_segments_split_at_the_recorded_switch(switched_bag):
    bag, r = switched_bag
    a = analyze_bag(bag)
    assert a.switches == [(0.0, "pd_pf"), (2.0, "pd_p")]
    assert [(s.controller, s.t_start, s.t_end, s.cycles) for s in a.segments] == [
        ("pd_pf", 0.0, 2.0, 2), ("pd_p", 2.0, 4.0, 2)]
    assert [c.controller for c in a.cycles] == ["pd_pf", "pd_pf", "pd_p", "pd_p"]
    # The PD-P segment's last cycle equals an in-process evaluation of the same samples.
    from hexapod_metrics.core.indices import indices_from_obs

    sl = slice(3000, 4001)
    ref = indices_from_obs(r.obs[sl], r.reference.hip[sl], r.reference.foot[sl], 1e-3)
    assert a.cycles[3].indices.eps_xH == pytest.approx(ref.eps_xH, rel=1e-12)
    assert a.segments[0].indices.eps_xH < a.segments[1].indices.eps_xH


def test_a_cut_bag_is_reported_as_truncated(switched_bag, tmp_path):
    bag, _ = switched_bag
    mcap = next(Path(bag).glob("*.mcap"))
    data = mcap.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    a = analyze_bag(cut)
    assert a.truncated and 0 < a.ticks < 4001 and len(a.cycles) >= 1


def _mutants(data: bytes, rng: np.random.Generator, n: int):
    yield "empty", b""
    yield "random", rng.bytes(5000)
    yield "magic only", data[:8]
    for k in range(n):
        kind = k % 3
        if kind == 0:
            yield f"cut {k}", data[: int(rng.integers(0, len(data)))]
        elif kind == 1:
            b = bytearray(data)
            for pos in rng.integers(0, len(b), size=int(rng.integers(1, 20))):
                b[pos] = int(rng.integers(0, 256))
            yield f"flip {k}", bytes(b)
        else:
            b = bytearray(data)
            at = int(rng.integers(0, len(b)))
            span = int(rng.integers(1, 4096))
            b[at:at + span] = rng.bytes(min(span, len(b) - at))
            yield f"smash {k}", bytes(b)


def _timeout(signum, frame):
    raise TimeoutError("analysis hung")


def test_fuzz_mutated_and_truncated_bags(tmp_path):
    p = load_params(**FAST)
    # small chunks: mutations that leave some chunks intact, a bag that still analyses
    small = write_run_bag(run(p, "pd_pf", 1.0), tmp_path / "small", chunk_size=256 * 1024)
    data = next(Path(small).glob("*.mcap")).read_bytes()
    rng = np.random.default_rng(11)
    old = signal.signal(signal.SIGALRM, _timeout)
    outcomes = {"ok": 0, "error": 0}
    try:
        for name, blob in _mutants(data, rng, 300):
            f = tmp_path / "m.mcap"
            f.write_bytes(blob)
            signal.alarm(20)
            try:
                analyze_bag(f)
                outcomes["ok"] += 1
            except BagReadError as err:
                msg = str(err)
                assert "\n" not in msg and msg, name
                outcomes["error"] += 1
            finally:
                signal.alarm(0)
    finally:
        signal.signal(signal.SIGALRM, old)
    assert outcomes["ok"] > 10 and outcomes["error"] > 10, outcomes


def test_bag_of_other_topics_and_not_a_bag_give_one_line_errors(tmp_path, hexapod):
    other = tmp_path / "other"
    with BagWriter(other) as w:
        w.write_joint_state("/arm/joint_states", 1, ["a"], [0.0], [0.0], [0.0])
    (tmp_path / "notabag").mkdir()
    (tmp_path / "notabag" / "x.txt").write_text("hello")
    for target, message in [(other, "not a hexapod bag"), (tmp_path / "notabag", ""),
                            (tmp_path / "missing", "")]:
        r = hexapod("analyze", str(target), "--no-plots")
        assert r.returncode == 2, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
        assert message in r.stderr


def test_analyze_cli_writes_tables_csv_and_plots(switched_bag, tmp_path, hexapod):
    bag, _ = switched_bag
    r = hexapod("analyze", str(bag), str(bag), "--csv", str(tmp_path / "a.csv"), "--out",
                str(tmp_path / "plots"))
    assert r.returncode == 0, r.stderr
    assert "switches: pd_p at 2.000 s" in r.stdout
    assert (tmp_path / "a.csv").read_text().count("segment") == 4
    assert sorted(x.name for x in (tmp_path / "plots").iterdir()) == [
        "Tm11.png", "Tm12.png", "dxH.png", "dyH.png", "indices.csv", "indices.json"]
    assert f"analysis written to {tmp_path / 'plots'}" in r.stdout


def test_analyze_writes_beside_the_bag_not_into_the_cwd(switched_bag, tmp_path, hexapod):
    bag, _ = switched_bag
    cwd = tmp_path / "elsewhere"
    cwd.mkdir()
    r = hexapod("analyze", str(bag), cwd=cwd)
    assert r.returncode == 0, r.stderr
    out = bag.with_name(bag.name + "_analysis")
    assert list(cwd.iterdir()) == []
    assert f"analysis written to {out}" in r.stdout
    assert sorted(x.name for x in out.iterdir()) == [
        "Tm11.png", "Tm12.png", "dxH.png", "dyH.png", "indices.csv", "indices.json"]
    assert (out / "indices.csv").read_text().count(",segment,") == 2
    assert not (bag / "analysis").exists()


def test_animate_writes_a_gif_with_one_panel_per_segment(switched_bag, tmp_path, hexapod):
    from PIL import Image

    from hexapod_bringup.animation import load_frames

    bag, r = switched_bag
    segments, l1, truncated = load_frames(bag, fps=5.0)
    assert [s.controller for s in segments] == ["pd_pf", "pd_p"] and not truncated
    np.testing.assert_array_equal(segments[1].obs[0], r.obs[2000])
    out = tmp_path / "walk.gif"
    r = hexapod("animate", str(bag), "--out", str(out), "--fps", "5")
    assert r.returncode == 0, r.stderr
    with Image.open(out) as im:
        assert im.n_frames == 11 and im.size[0] > 2 * im.size[1]
