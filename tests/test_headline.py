"""The README's headline table is the one `hexapod reproduce --readme` writes from the
committed report's results (report/results.json): both verdicts of every claim, at every
window on the paper's indices and on the stationary ones, one sentence for each."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from hexapod_bringup.report_headline import (BEGIN, END, NOT_DECIDED, headline_lines,
                                             readme_block, write_readme)

ROOT = Path(__file__).resolve().parents[1]


def _claims():
    return json.loads((ROOT / "report" / "results.json").read_text())["claims"]


def test_the_readme_headline_is_the_committed_reports():
    readme = (ROOT / "README.md").read_text()
    assert readme_block(_claims()) in readme


def test_a_report_without_window_verdicts_says_so_instead_of_guessing():
    claims = [{"claim": "C1", "statement": "s", "status": "fails"}]
    lines = headline_lines(claims)
    assert lines[2] == f"| C1 | s | **fails** | {NOT_DECIDED} | {NOT_DECIDED} |"
    assert all(NOT_DECIDED in line for line in lines[-2:])


def test_the_headline_has_both_verdicts_and_a_sentence_each():
    claims = [{"claim": "C1", "statement": "s1", "status": "fails",
               "window_statuses": ["fails"] * 2 + ["holds"] * 18,
               "stationary_statuses": ["fails"] * 20},
              {"claim": "C2", "statement": "s2", "status": "holds",
               "window_statuses": ["holds"] * 20, "stationary_statuses": ["holds"] * 20}]
    lines = headline_lines(claims)
    assert lines[2] == ("| C1 | s1 | **fails** | depends on the window: fails in cycles 1-2, "
                        "holds from cycle 3 | fails in every window (cycles 1-20) |")
    assert lines[-2].startswith("On the paper's indices") and lines[-2].endswith(
        "C1 depends on the window, C2 holds in every one.")
    assert lines[-1].startswith("On the stationary indices") and lines[-1].endswith(
        "C1 fails in every one, C2 holds in every one.")


def test_write_readme_replaces_only_the_block_and_needs_the_markers(tmp_path):
    claims = [{"claim": "C1", "statement": "s", "status": "holds",
               "window_statuses": ["holds"] * 20, "stationary_statuses": ["holds"] * 20}]
    path = tmp_path / "README.md"
    path.write_text(f"before\n{BEGIN}\nold table\n{END}\nafter\n")
    write_readme(path, claims)
    assert path.read_text() == f"before\n{readme_block(claims)}\nafter\n"
    path.write_text("no markers\n")
    with pytest.raises(ValueError, match="no headline markers"):
        write_readme(path, claims)


@pytest.mark.parametrize("content", [None, "a README without the markers\n"])
def test_reproduce_refuses_a_readme_without_the_markers_in_one_line(hexapod, tmp_path,
                                                                    content):
    path = tmp_path / "README.md"
    if content is not None:
        path.write_text(content)
    r = hexapod("reproduce", "--quick", "--readme", str(path), "--out", str(tmp_path / "r"))
    assert r.returncode != 0 and not (tmp_path / "r").exists()
    assert len(r.stderr.strip().splitlines()) == 1 and "--readme" in r.stderr
