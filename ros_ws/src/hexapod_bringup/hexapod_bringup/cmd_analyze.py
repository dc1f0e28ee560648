"""`hexapod analyze BAG...`: indices per controller segment and per gait cycle, CSV/JSON, plots;
`hexapod reindex BAG`: a cut-short bag rewritten complete, for the other readers."""
from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path

from hexapod_metrics.bag import reindex
from hexapod_metrics.core.analysis import BagAnalysis, SegmentResult, analyze_bag
from hexapod_metrics.core.indices import (DRIFT_NAMES, INDEX_NAMES, REPORTED_NAMES, Indices,
                                         lag_growth)

#: Exit code of ``hexapod analyze`` when a segment had a cycle that was not a walk.
EXIT_FALLEN = 8


#: The columns of the per-cycle table: the seven, the hip lag and the drift indices.
CYCLE_COLUMNS = INDEX_NAMES + ("lag_xH",) + DRIFT_NAMES


def _fmt(idx: Indices | None, name: str) -> str:
    return "-" if idx is None else f"{getattr(idx, name):.5g}"


def _changed(s: SegmentResult) -> str:
    """' name=value,...' of the parameters changed since the start, '' if none."""
    return (" " + ",".join(f"{n}={v:g}" if isinstance(v, float) else f"{n}={v}"
                           for n, v in s.params)) if s.params else ""


def _own(s: SegmentResult) -> str:
    """'name=value,...' of a joined controller's own parameters ('' for the engine's)."""
    return ",".join(f"{n}={v:g}" if isinstance(v, float) else f"{n}={v}"
                    for n, v in s.controller_params)


def _rows(a: BagAnalysis) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    for s in a.segments:
        rows.append({"bag": str(a.path), "kind": "segment", "controller": s.controller,
                     "cycle": "", "t_start": s.t_start, "t_end": s.t_end, "cycles": s.cycles,
                     "params_changed": _changed(s).strip(),
                     **{n: getattr(s.indices, n) if s.indices else math.nan
                        for n in REPORTED_NAMES},
                     "controller_params": _own(s)})
    for c in a.cycles:
        idx = c.indices
        rows.append({"bag": str(a.path), "kind": "cycle", "controller": c.controller,
                     "cycle": c.cycle, "t_start": c.t_a, "t_end": c.t_b, "cycles": 1,
                     "params_changed": "",
                     **{n: getattr(idx, n) if idx else math.nan for n in REPORTED_NAMES},
                     "controller_params": ""})
    return rows


def _print(analyses: list[BagAnalysis], per_cycle: bool) -> None:
    for a in analyses:
        note = f"  TRUNCATED: {a.truncation_reason}" if a.truncated else ""
        print(f"{a.path}: {a.ticks} ticks, {len(a.cycles)} full gait cycles, parameters "
              f"{a.params_source}{note}")
        if len(a.switches) > 1:
            print("  switches: " + ", ".join(f"{c} at {t:.3f} s" for t, c in a.switches[1:]))
        for s in a.segments:
            if s.controller_params:
                print(f"  {s.controller} [{s.t_start:g}-{s.t_end:g}s] ran with its own "
                      f"parameters (read from its node at the switch): {_own(s)}")
        if a.param_changes:
            print("  parameter changes (applied from that tick on): " + ", ".join(
                f"{n} = {v!r} at {t:.3f} s ({node})" for t, node, n, v in a.param_changes))
    cols = [(a, s) for a in analyses for s in a.segments]
    many = len(analyses) > 1
    heads = [f"{(a.path.name + ':') if many else ''}{s.controller} "
             f"[{s.t_start:g}-{s.t_end:g}s]{_changed(s)}" for a, s in cols]
    width = max([14] + [len(h) + 1 for h in heads])
    print(f"\n{'segment':<8}" + "".join(f"{h:>{width}}" for h in heads))
    print(f"{'cycles':<8}" + "".join(f"{s.cycles:>{width}}" for _, s in cols))
    for n in REPORTED_NAMES:
        print(f"{n:<8}" + "".join(f"{'fallen' if s.fallen else _fmt(s.indices, n):>{width}}"
                                  for _, s in cols))
    for _, s in cols:
        if s.fallen:
            print(f"{s.controller} [{s.t_start:g}-{s.t_end:g}s]: no indices, {s.fallen}")
    if per_cycle:
        for a in analyses:
            print(f"\n{a.path.name}: per gait cycle")
            print(f"{'cycle':>5} {'t_a':>7} {'controller':>10} " +
                  " ".join(f"{n:>10}" for n in CYCLE_COLUMNS) +
                  f" {'lag growth':>10}")
            prev = None
            for c in a.cycles:
                idx = c.indices
                growth = lag_growth(prev.indices, idx) if prev is not None and \
                    prev.cycle == c.cycle - 1 else math.nan
                vals = (" ".join(f"{_fmt(idx, n):>10}" for n in CYCLE_COLUMNS)
                        + f" {growth:>10.3g}" if idx else c.fallen if c.fallen else
                        f"incomplete: {c.missing} ticks missing")
                print(f"{c.cycle:>5} {c.t_a:>7.3g} {c.controller:>10} {vals}")
                prev = c


def _plots(analyses: list[BagAnalysis], out: Path) -> list[Path]:
    from hexapod_bringup import plots

    out.mkdir(parents=True, exist_ok=True)
    many = len(analyses) > 1
    series: dict[str, dict[str, tuple]] = {k: {} for k in plots.TIME_SIGNALS}
    for a in analyses:
        t, values, labels = a.series.arrays()
        for who in dict.fromkeys(labels):
            sel = labels == who
            name = f"{a.path.name}:{plots.label(who)}" if many else who
            for j, key in enumerate(plots.TIME_SIGNALS):
                # NaN between separate stretches of one controller so lines do not jump
                tt = t[sel].astype(float)
                vv = values[sel, j].astype(float)
                gaps = tt[1:] - tt[:-1] > 2 * a.series.stride * a.params.sim.control_period
                if gaps.any():
                    cut = 1 + gaps.nonzero()[0]
                    tt = insert_nan(tt, cut)
                    vv = insert_nan(vv, cut)
                series[key][name] = (tt, vv)
    paths = []
    for key, (title, _) in plots.TIME_SIGNALS.items():
        path = out / f"{key}.png"
        plots.time_plot(series[key], key, path, f"{title} of leg 1")
        paths.append(path)
    return paths


def insert_nan(a, where):  # type: ignore[no-untyped-def]
    """``a`` with NaN inserted before each index in ``where``."""
    import numpy as np

    return np.insert(a, where, np.nan)


def beside(bag: str | Path, suffix: str) -> Path:
    """``BAG<suffix>`` in the bag's own directory (a bag directory or an .mcap file; '.' and
    '..' are resolved first so the name is the bag's)."""
    path = Path(bag)
    if path.name in ("", ".", ".."):
        path = path.resolve()
    return path.with_name(path.name.removesuffix(".mcap") + suffix)


def default_out(bags: list[str]) -> Path:
    """Where `analyze` writes without --out: ``BAG_analysis`` beside the bag; for several bags
    beside the first, named after all of them (or the first and a count)."""
    if len(bags) == 1:
        return beside(bags[0], "_analysis")
    names = [beside(b, "").name for b in bags]
    joined = "+".join(names)
    tag = joined if len(joined) <= 80 else f"{names[0]}+{len(names) - 1}_more"
    return beside(bags[0], "").with_name(tag + "_analysis")


def _write_csv(rows: list[dict[str, object]], path: Path) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def _cmd_analyze(args: argparse.Namespace) -> int:
    analyses = [analyze_bag(b) for b in args.bags]
    _print(analyses, args.cycles)
    rows = [r for a in analyses for r in _rows(a)]
    out = Path(args.out) if args.out else default_out(args.bags)
    out.mkdir(parents=True, exist_ok=True)
    _write_csv(rows, out / "indices.csv")
    (out / "indices.json").write_text(json.dumps(rows, indent=1, default=float))
    print(f"\ntables: {out / 'indices.csv'}, {out / 'indices.json'}")
    if args.csv:
        _write_csv(rows, Path(args.csv))
        print(f"CSV: {args.csv}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=float))
        print(f"JSON: {args.json}")
    if not args.no_plots:
        paths = _plots(analyses, out)
        print("plots: " + ", ".join(str(p) for p in paths))
    print(f"analysis written to {out}")
    if any(s.fallen for a in analyses for s in a.segments):
        return EXIT_FALLEN  # said above, per segment
    return 0


def _cmd_reindex(args: argparse.Namespace) -> int:
    src = Path(args.bag)
    out = Path(args.out) if args.out else src.with_name(src.name + "_reindexed")
    r = reindex(src, out)
    print(f"{r.path}: {r.messages} messages on {r.topics} topics from {src} ({r.reason}); "
          "indexed, opens in any MCAP reader")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register `analyze` and `reindex`."""
    rp = sub.add_parser("reindex", help="rewrite a cut-short bag (killed recorder) as a "
                        "complete, indexed one")
    rp.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    rp.add_argument("--out", help="new bag directory (default BAG_reindexed)")
    rp.set_defaults(func=_cmd_reindex)
    ap = sub.add_parser("analyze", help="indices of recorded bags, per segment and gait cycle")
    ap.add_argument("bags", nargs="+", metavar="BAG", help="bag directory or .mcap file")
    ap.add_argument("--cycles", action="store_true", help="also print every gait cycle")
    ap.add_argument("--out", "--plots", dest="out", metavar="DIR",
                    help="directory for the tables (indices.csv, indices.json) and the PNG "
                    "time plots (default: beside the bag, BAG_analysis; printed)")
    ap.add_argument("--csv", help="also write segments and cycles to this CSV file")
    ap.add_argument("--json", help="also write segments and cycles to this JSON file")
    ap.add_argument("--no-plots", action="store_true", help="skip the plots")
    ap.set_defaults(func=_cmd_analyze)


__all__ = ["add_parser", "beside", "default_out"]
