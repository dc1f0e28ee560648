"""The Foxglove layout of this project, built with ``foxglove.layouts`` (foxglove-sdk).

``python -m hexapod_metrics.foxglove_layout [FILE]`` writes it (default: stdout); the
repository keeps the result in ``docs/foxglove/hexapod_layout.json`` (a test checks that
the two agree). Panels: the 3-D view of ``/hexapod/markers`` (frame ``world``); plots of
leg 1's hip tracking errors |Δ1xH|, |Δ1yH| (m), its joint torques T_m11, T_m12 (N m), and
of the seven indices of each gait cycle; the raw parameter records and sim status.

Foxglove's expressions cannot subtract two topics, nor plot the indices (strings in a
DiagnosticArray), so two user scripts saved in the layout derive them from recorded
topics; their outputs live under ``/foxglove_script/`` inside Foxglove only. Everything
else the layout names is a recorded topic (core/recording.py ``TOPICS``), so it opens with
any bag of the project and with the live server (foxglove_node.py).
"""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

from hexapod_common.core import topics as T

from .core.indices import INDEX_NAMES

HIP_ERROR = "/foxglove_script/hexapod_hip_error_leg1"
INDICES = "/foxglove_script/hexapod_indices"
#: Where the repository keeps the layout (relative to the repository root).
LAYOUT_FILE = Path("docs/foxglove/hexapod_layout.json")

HIP_ERROR_SCRIPT = f"""\
// |Δ1xH|, |Δ1yH|: leg 1's hip position error (reference - hip state), in m, per tick.
// Pairs {T.REFERENCE} and {T.HIP_STATES} by header stamp (either may come first).
import {{ Input }} from "./types";

type Output = {{ abs_dx_1H: number; abs_dy_1H: number; dx_1H: number; dy_1H: number }};
type Pair = {{ ref?: [number, number]; hip?: [number, number] }};

export const inputs = ["{T.REFERENCE}", "{T.HIP_STATES}"];
export const output = "{HIP_ERROR}";

const pending = new Map<number, Pair>();

function leg1Hip(msg: any): [number, number] {{
  const ix = msg.name.indexOf("leg1_hip_x");
  const iy = msg.name.indexOf("leg1_hip_y");
  return [msg.position[ix], msg.position[iy]];
}}

export default function script(
  event: Input<"{T.REFERENCE}"> | Input<"{T.HIP_STATES}">,
): Output | undefined {{
  const msg: any = event.message;
  const stamp = msg.header.stamp.sec * 1e9 + msg.header.stamp.nanosec;
  const pair = pending.get(stamp) ?? {{}};
  if (event.topic === "{T.REFERENCE}") pair.ref = leg1Hip(msg);
  else pair.hip = leg1Hip(msg);
  if (!pair.ref || !pair.hip) {{
    pending.set(stamp, pair);
    if (pending.size > 1000) pending.delete(pending.keys().next().value as number);
    return undefined;
  }}
  pending.delete(stamp);
  const dx = pair.ref[0] - pair.hip[0];
  const dy = pair.ref[1] - pair.hip[1];
  return {{ abs_dx_1H: Math.abs(dx), abs_dy_1H: Math.abs(dy), dx_1H: dx, dy_1H: dy }};
}}
"""

INDICES_SCRIPT = f"""\
// The indices of each gait cycle ({T.INDICES}, strings in a DiagnosticArray) as numbers.
import {{ Input }} from "./types";

type Output = {{ {"; ".join(f"{n}: number" for n in INDEX_NAMES + ("L", "cycle"))} }};

export const inputs = ["{T.INDICES}"];
export const output = "{INDICES}";

export default function script(event: Input<"{T.INDICES}">): Output | undefined {{
  const status: any = event.message.status[0];
  if (!status) return undefined;
  const kv = new Map<string, string>(status.values.map((v: any) => [v.key, v.value]));
  const num = (k: string) => Number(kv.get(k) ?? NaN);
  return {{ {", ".join(f"{n}: num({n!r})" for n in INDEX_NAMES + ("L", "cycle"))} }};
}}
""".replace("'", '"')


def build_layout():  # type: ignore[no-untyped-def]
    """The layout as a ``foxglove.layouts.Layout``."""
    import foxglove.layouts as fl

    def plot(title: str, series: list[tuple[str, str]]) -> object:
        return fl.PlotPanel(title=title, config=fl.PlotConfig(paths=[
            fl.PlotSeries(value=value, label=label, timestamp_method="receiveTime")
            for value, label in series]))

    three_d = fl.ThreeDeePanel(title="hexapod (markers)", config=fl.ThreeDeeConfig(
        follow_tf="world",
        topics={T.MARKERS: fl.BaseRendererRosMarkerTopicSettings(visible=True)}))
    errors = plot("leg 1 hip errors |Δ1xH|, |Δ1yH| (m)",
                  [(f"{HIP_ERROR}.abs_dx_1H", "|Δ1xH|"), (f"{HIP_ERROR}.abs_dy_1H", "|Δ1yH|")])
    torques = plot("leg 1 joint torques (N m)",
                   [(f"{T.JOINT_STATES}.effort[0]", "T_m11"),
                    (f"{T.JOINT_STATES}.effort[1]", "T_m12")])
    tracking = plot("tracking indices per gait cycle (m)",
                    [(f"{INDICES}.{n}", n) for n in INDEX_NAMES if n.startswith("eps")])
    effort = plot("effort indices per gait cycle",
                  [(f"{INDICES}.{n}", n) for n in INDEX_NAMES if not n.startswith("eps")])
    params = fl.RawMessagesPanel(title="parameter records",
                                 config=fl.RawMessagesConfig(topic_path=T.PARAMETERS))
    status = fl.RawMessagesPanel(title="sim status",
                                 config=fl.RawMessagesConfig(topic_path=f"{T.STATUS}.status[0]"))

    def column(*panels: object) -> object:
        return fl.SplitContainer(direction="column",
                                 items=[fl.SplitItem(content=p) for p in panels])

    return fl.Layout(
        user_scripts={
            "hip_error": fl.UserScript(name="leg 1 hip error", source_code=HIP_ERROR_SCRIPT),
            "indices": fl.UserScript(name="indices as numbers", source_code=INDICES_SCRIPT),
        },
        content=fl.SplitContainer(direction="row", items=[
            fl.SplitItem(proportion=1.2, content=column(three_d, fl.SplitContainer(
                direction="row", items=[fl.SplitItem(content=params),
                                        fl.SplitItem(content=status)]))),
            fl.SplitItem(proportion=1, content=column(errors, torques, tracking, effort)),
        ]))


def layout_json() -> str:
    """The layout file's text (indented JSON, newline at the end)."""
    return json.dumps(json.loads(build_layout().to_json()), indent=1, ensure_ascii=False) + "\n"


_TOPIC = re.compile(r"^(/[A-Za-z0-9_/]+)")
_INPUTS = re.compile(r"export const inputs = \[([^\]]*)\]")
_OUTPUT = re.compile(r'export const output = "([^"]+)"')


def layout_topics(doc: dict[str, Any]) -> tuple[set[str], set[str]]:
    """(topics the layout reads from its data source, topics its user scripts produce).

    Read: 3-D panel topics, the topic of every plot series and raw-message path, the
    scripts' inputs; a plot of a script's output counts as produced, not read.
    """
    scripts = (doc.get("userScripts") or {}).values()
    produced = {m.group(1) for s in scripts for m in [_OUTPUT.search(s["sourceCode"])] if m}
    read = {t.strip().strip('"') for s in scripts for m in [_INPUTS.search(s["sourceCode"])]
            if m for t in m.group(1).split(",") if t.strip()}

    def walk(node: Any) -> None:
        if isinstance(node, dict):
            if node.get("panelType") == "ThreeDee":
                read.update((node.get("config") or {}).get("topics") or {})
            for key in ("value", "topicPath"):
                m = _TOPIC.match(str(node.get(key, "")))
                if m:
                    read.add(m.group(1))
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(doc.get("content"))
    return read - produced, produced


def main(argv: list[str] | None = None) -> int:
    """Write the layout to the file named in ``argv`` (or stdout)."""
    args = sys.argv[1:] if argv is None else argv
    text = layout_json()
    if args:
        Path(args[0]).parent.mkdir(parents=True, exist_ok=True)
        Path(args[0]).write_text(text, encoding="utf-8")
    else:
        sys.stdout.write(text)
    return 0


__all__ = ["HIP_ERROR", "INDICES", "LAYOUT_FILE", "build_layout", "layout_json", "layout_topics",
           "main"]

if __name__ == "__main__":
    sys.exit(main())
