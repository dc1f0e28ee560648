"""The Foxglove layout in the repository: generated from the code, names only recorded topics."""
import json
from pathlib import Path

from hexapod_metrics.core.recording import TOPICS, write_run_bag
from hexapod_metrics.foxglove_layout import (HIP_ERROR, INDICES, LAYOUT_FILE, layout_json,
                                             layout_topics)
from hexapod_common.core import topics as T

ROOT = Path(__file__).resolve().parents[1]


def test_the_layout_file_is_the_generated_one():
    assert (ROOT / LAYOUT_FILE).read_text(encoding="utf-8") == layout_json(), (
        "regenerate it: python -m hexapod_metrics.foxglove_layout " + str(LAYOUT_FILE))


def test_the_layout_reads_only_recorded_topics_and_plots_what_the_issue_asks():
    doc = json.loads((ROOT / LAYOUT_FILE).read_text(encoding="utf-8"))
    read, produced = layout_topics(doc)
    assert produced == {HIP_ERROR, INDICES}
    assert read <= set(TOPICS), read - set(TOPICS)
    assert {T.MARKERS, T.JOINT_STATES, T.REFERENCE, T.HIP_STATES, T.INDICES} <= read
    text = json.dumps(doc, ensure_ascii=False)
    for series in ("|Δ1xH|", "|Δ1yH|", "T_m11", "T_m12", "eps_xH", "E_av", "T_L", "F_L"):
        assert f'"label": "{series}"' in text
    assert f"{T.JOINT_STATES}.effort[0]" in text and f"{T.JOINT_STATES}.effort[1]" in text


def test_an_in_process_bag_has_every_topic_the_plots_read(tmp_path):
    """A `hexapod simulate` bag: everything but the graph-only markers and sim status."""
    from hexapod_control.core.closed_loop import run
    from hexapod_metrics.bag import open_bag
    from hexapod_common.core.params import load_params

    doc = json.loads((ROOT / LAYOUT_FILE).read_text(encoding="utf-8"))
    read, _ = layout_topics(doc)
    p = load_params(**{"sim.dt": 1e-4, "sim.control_period": 1e-3})  # small and quick
    bag = write_run_bag(run(p, "pd_pf", 1.0), tmp_path / "bag")
    with open_bag(bag) as b:
        assert read - {T.MARKERS, T.STATUS} <= set(b.topics)
