"""`hexapod reindex`: a bag torn by a kill inside a chunk's write, rewritten complete
(hexapod_metrics.bag.reindex): the other readers open the copy, it holds exactly what our
reader read of the torn bag, analyses the same and says it was cut short."""
from __future__ import annotations

import contextlib
import io
import shutil
from pathlib import Path

import pytest

from hexapod_control.core.closed_loop import run
from hexapod_metrics.bag import REINDEXED, BagWriteError, open_bag, reindex
from hexapod_metrics.core.analysis import analyze_bag
from hexapod_metrics.core.recording import write_run_bag
from hexapod_common.core.params import load_params

FAST = {"sim.dt": 1e-4, "sim.control_period": 1e-3}


@pytest.fixture(scope="module")
def torn(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s bag whose MCAP ends inside its last chunk, as a SIGKILL mid-pwrite leaves it."""
    root = tmp_path_factory.mktemp("reindex")
    whole = write_run_bag(run(load_params(**FAST), "pd_pf", 3.0), root / "whole",
                          chunk_size=256 * 1024)
    bag = root / "torn"
    bag.mkdir()
    shutil.copy(whole / "metadata.yaml", bag / "metadata.yaml")
    data = (whole / "whole_0.mcap").read_bytes()
    (bag / "whole_0.mcap").write_bytes(data[:len(data) - 100_000])
    return bag


def _messages(path: Path) -> list[tuple[str, int, bytes]]:
    with open_bag(path, require_joint_states=False) as bag:
        return list(bag.messages())


def test_the_torn_bag_is_refused_by_the_mcap_library_and_read_by_ours(torn: Path) -> None:
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    with open(torn / "whole_0.mcap", "rb") as fh, pytest.raises((McapError, ValueError)):
        make_reader(fh).get_summary()
    with open_bag(torn) as bag:
        assert bag.truncated and "inside a record" in bag.truncation_reason
        assert bag.message_count > 1000


def test_reindexed_copy_opens_everywhere_with_the_same_messages(torn: Path,
                                                                tmp_path: Path) -> None:
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    out = reindex(torn, tmp_path / "copy")
    before = _messages(torn)
    assert out.messages == len(before) and out.path == tmp_path / "copy"
    assert _messages(out.path) == before  # topic, log time and bytes, in order
    with open(next(out.path.glob("*.mcap")), "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None and summary.chunk_indexes
        assert sum(summary.statistics.channel_message_counts.values()) == len(before)
        names = [m.name for m in reader.iter_metadata()]
    assert REINDEXED in names and "hexapod_parameters" in names
    with AnyReader([out.path]) as r:
        assert sum(1 for _ in r.messages()) == len(before)
    with open_bag(torn) as a, open_bag(out.path) as b:
        assert {t.name: (t.msgtype, t.offered_qos_profiles, t.type_hash)
                for t in a.topics.values()} == {
            t.name: (t.msgtype, t.offered_qos_profiles, t.type_hash) for t in b.topics.values()}
        assert b.truncated and "reindexed from" in b.truncation_reason
        assert a.truncation_reason in b.truncation_reason


def test_reindexed_copy_analyses_as_the_torn_bag(torn: Path, tmp_path: Path) -> None:
    copy = reindex(torn, tmp_path / "copy").path
    a, b = analyze_bag(torn), analyze_bag(copy)
    assert b.truncated and a.ticks == b.ticks and a.params == b.params
    assert [(c.cycle, c.controller, c.indices) for c in a.cycles] == [
        (c.cycle, c.controller, c.indices) for c in b.cycles]


def test_reindex_refuses_an_existing_directory_and_the_cli_says_so_in_one_line(
        torn: Path, tmp_path: Path) -> None:
    from hexapod_bringup.cli import main

    (tmp_path / "taken").mkdir()
    junk = tmp_path / "junk"
    junk.mkdir()
    (junk / "junk_0.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 40)
    with pytest.raises(BagWriteError, match="already exists"):
        reindex(torn, tmp_path / "taken")
    for args in (["reindex", str(torn), "--out", str(tmp_path / "taken")],
                 ["reindex", str(tmp_path / "nothing")],
                 ["reindex", str(junk), "--out", str(tmp_path / "from_junk")]):
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            assert main(args) == 2
        lines = err.getvalue().strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("hexapod reindex: error: "), lines
    assert not (tmp_path / "from_junk").exists()
