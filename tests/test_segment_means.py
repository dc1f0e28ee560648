"""A segment of several gait cycles reports the per-cycle mean of every index (model.md, "The
window": T_L and F_L are not additive, the index of the union of N cycles is ~1/sqrt(N) of
one cycle's), in `hexapod analyze`, in the recorder's segment table (indices.json) and in
run_graph.sh's summary, which print the drift per segment; /hexapod/indices carries each
cycle's drift."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hexapod_bringup.graph_launcher import indices_lines
from hexapod_common.core.params import load_params
from hexapod_control.core.closed_loop import run
from hexapod_metrics.core.analysis import analyze_bag
from hexapod_metrics.core.cycles import Cycle, segments
from hexapod_metrics.core.indices import REPORTED_NAMES, per_cycle_mean, sums_from_obs
from hexapod_metrics.core.recording import indices_status, status_indices, write_run_bag

pytestmark = pytest.mark.xdist_group("test_segment_means")

#: analysis behaviour, not the paper's numbers: model.md's 1e-4 s physics, 1 kHz control
FAST = {"sim.dt": 1e-4, "sim.control_period": 1e-3}


@pytest.fixture(scope="module")
def three_then_two(tmp_path_factory):
    """PD-P&F for 3 cycles, then PD-P for 2: the bag and the run."""
    p = load_params(**FAST)
    r = run(p, "pd_pf", 5.0, switches=[(3.0, "pd_p")])
    return write_run_bag(r, tmp_path_factory.mktemp("bags") / "three_two"), r


def _cycles(r) -> list[Cycle]:
    """Every full gait cycle of the run, scored as the recorder scores them."""
    m, dt = 1000, 1e-3
    out = []
    for c in range(5):
        sl = slice(c * m, (c + 1) * m + 1)
        who = "pd_pf" if c < 3 else "pd_p"
        sums = sums_from_obs(r.obs[sl], r.reference.hip[sl], r.reference.foot[sl], dt)
        out.append(Cycle(c, c * 1.0, (c + 1) * 1.0, who, who, 0, sums))
    return out


def test_analyze_reports_the_per_cycle_mean_not_the_union(three_then_two):
    bag, r = three_then_two
    a = analyze_bag(bag)
    assert [(s.controller, s.cycles) for s in a.segments] == [("pd_pf", 3), ("pd_p", 2)]
    for seg, cycles in ((a.segments[0], a.cycles[:3]), (a.segments[1], a.cycles[3:])):
        for name in REPORTED_NAMES:
            want = np.mean([getattr(c.indices, name) for c in cycles])
            assert getattr(seg.indices, name) == pytest.approx(want, rel=1e-12), name
    # the union of the three cycles would score T_L and F_L about 1/sqrt(3) of a cycle's
    union = (a.cycles[0].sums + a.cycles[1].sums + a.cycles[2].sums).indices()
    assert union.T_L < 0.7 * a.segments[0].indices.T_L
    assert a.segments[0].indices.T_L == pytest.approx(a.cycles[2].indices.T_L, rel=0.05)


def test_analyze_prints_the_drift_per_segment(three_then_two, hexapod, tmp_path):
    bag, _ = three_then_two
    out = hexapod("analyze", str(bag), "--no-plots", "--out", str(tmp_path / "a"))
    a = analyze_bag(bag)
    rows = {line.split()[0]: line.split()[1:] for line in out.stdout.splitlines()
            if line.split() and line.split()[0] in ("drift_xH", "drift_xF", "T_L")}
    for name in ("drift_xH", "drift_xF", "T_L"):
        assert [float(v) for v in rows[name]] == pytest.approx(
            [getattr(s.indices, name) for s in a.segments], rel=1e-4), name


def test_recorder_segments_and_run_graph_summary_give_the_per_cycle_mean(three_then_two,
                                                                         tmp_path):
    _, r = three_then_two
    cycles = _cycles(r)
    segs = segments(cycles, [(0, "pd_pf"), (3000, "pd_p")], 1e-3, 5000)
    assert [s["mean_cycles"] for s in segs] == [[0, 1, 2], [3, 4]]
    for s, own in zip(segs, (cycles[:3], cycles[3:])):
        want = per_cycle_mean([c.indices for c in own])
        assert s["per_cycle_mean"] == want.as_dict()
    doc = {"index_names": list(REPORTED_NAMES), "segments": segs,
           "cycles": [c.as_dict() for c in cycles], "parameter_changes": []}
    path = tmp_path / "indices.json"
    path.write_text(json.dumps(doc))
    lines = indices_lines(path)
    assert "per-cycle mean" in lines[0]
    head = lines[1].split()
    assert "drift_xH" in head and "drift_xF" in head
    rows = [line for line in lines[2:] if not line.strip().startswith("^")]
    assert len(rows) == 2
    for row, s in zip(rows, segs):
        cells = row.split()
        assert cells[0] == s["controller"]
        values = [float(v) for v in cells[-len(REPORTED_NAMES):]]
        assert values == pytest.approx([s["per_cycle_mean"][n] for n in REPORTED_NAMES],
                                       rel=1e-3)
    # what `hexapod analyze` prints for the same run
    assert rows[0].split()[3] == "3:" and rows[1].split()[3] == "2:"


def test_a_segment_whose_cycle_fell_has_no_mean(three_then_two, tmp_path):
    _, r = three_then_two
    cycles = _cycles(r)
    fell = Cycle(1, 1.0, 2.0, "pd_pf", "pd_pf", 0, cycles[1].sums, fallen="hips sank")
    cycles[1] = fell
    segs = segments(cycles, [(0, "pd_pf"), (3000, "pd_p")], 1e-3, 5000)
    assert segs[0]["per_cycle_mean"] is None and segs[0]["fallen"] == "cycle 1: hips sank"
    path = tmp_path / "indices.json"
    path.write_text(json.dumps({"index_names": list(REPORTED_NAMES), "segments": segs,
                                "cycles": [c.as_dict() for c in cycles]}))
    assert "no indices: cycle 1: hips sank" in indices_lines(path)[2]


def test_each_cycle_on_hexapod_indices_carries_its_drift(three_then_two):
    _, r = three_then_two
    c = _cycles(r)[2]
    idx, kv = status_indices(indices_status(c))
    assert c.indices is not None
    for name in ("drift_xH", "drift_xF", "trk_xH", "trk_xF"):
        assert getattr(idx, name) == getattr(c.indices, name)
    assert kv["controller"] == "pd_pf" and kv["cycle"] == "2"
