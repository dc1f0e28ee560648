"""The reproduction's headline: the claims C1-C4 decided on the paper's window, at every
window on the paper's indices and at every window on the stationary ones, one table and one
sentence for each way of deciding. `hexapod reproduce` puts it at the top of the report and,
with ``--readme FILE``, between the headline markers of the repository's README
(tests/test_headline.py checks that README and report/results.json agree)."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Mapping, Sequence

from .core.windows import DEPENDS, FIRST_WINDOW, WindowVerdict

#: The lines around the headline in a README.
BEGIN = ("<!-- headline: written by `hexapod reproduce --readme README.md` from "
         "report/results.json -->")
END = "<!-- end of the headline -->"


#: What the window columns say of a report written before claims were decided at every
#: window (its results.json has no window statuses).
NOT_DECIDED = "not in this report (written before the window rule: regenerate it)"


def _verdicts(claims: Sequence[Mapping[str, Any]], key: str) -> list[WindowVerdict] | None:
    if not all(c.get(key) for c in claims):
        return None
    return [WindowVerdict(c["claim"], tuple(c[key]), FIRST_WINDOW) for c in claims]


def _sentence(what: str, verdicts: Sequence[WindowVerdict] | None) -> str:
    """'On WHAT, at every window (gait cycles 1-20): C1 and C2 depend on the window, C3
    holds in every one, C4 is undecided in every one.'"""
    if verdicts is None:
        return f"On {what}, at every window: {NOT_DECIDED}."
    groups: dict[str, list[str]] = {}
    for v in verdicts:
        groups.setdefault(v.status, []).append(v.claim)
    parts = []
    for status, names in groups.items():
        who = " and ".join([", ".join(names[:-1]), names[-1]] if len(names) > 1 else names)
        plural = len(names) > 1
        if status == DEPENDS:
            parts.append(f"{who} depend{'' if plural else 's'} on the window")
        else:
            verb = {"holds": "hold" if plural else "holds", "fails": "fail" if plural else
                    "fails"}.get(status, ("are " if plural else "is ") + status)
            parts.append(f"{who} {verb} in every one")
    last = FIRST_WINDOW + len(verdicts[0].statuses) - 1 if verdicts else FIRST_WINDOW
    return f"On {what}, at every window (gait cycles {FIRST_WINDOW}-{last}): " + \
        ", ".join(parts) + "."


def headline_lines(claims: Sequence[Mapping[str, Any]]) -> list[str]:
    """The headline table and its two sentences, from results.json's ``claims``."""
    paper = _verdicts(claims, "window_statuses")
    steady = _verdicts(claims, "stationary_statuses")
    out = ["| claim | statement | paper's window (last cycle of the run) | paper's indices, "
           "every window | stationary indices, every window |", "|---|---|---|---|---|"]
    for j, c in enumerate(claims):
        p = paper[j].text() if paper else NOT_DECIDED
        s = steady[j].text() if steady else NOT_DECIDED
        out.append(f"| {c['claim']} | {c['statement']} | **{c['status']}** | {p} | {s} |")
    return out + ["", _sentence("the paper's indices, whose horizontal errors grow with the "
                                "drift", paper),
                  _sentence("the stationary indices (trk_xH, trk_xF for eps_xH, eps_xF: the "
                            "drift taken out)", steady)]


def readme_block(claims: Sequence[Mapping[str, Any]]) -> str:
    """The headline with its markers, as a README holds it."""
    return "\n".join([BEGIN, *headline_lines(claims), END])


def write_readme(path: Path, claims: Sequence[Mapping[str, Any]]) -> None:
    """Replace the headline between the markers of the README at ``path``."""
    text = path.read_text()
    pattern = re.compile(re.escape(BEGIN) + ".*?" + re.escape(END), re.S)
    if not pattern.search(text):
        raise ValueError(f"{path}: no headline markers ({BEGIN!r} ... {END!r})")
    path.write_text(pattern.sub(lambda m: readme_block(claims), text, count=1))


__all__ = ["BEGIN", "END", "NOT_DECIDED", "headline_lines", "readme_block", "write_readme"]
