#!/usr/bin/env python3
"""Benchmark (quality bar S6): decode a JointState bag into arrays.

Writes a bag of ``--messages`` JointStates (12 joints, smooth signals plus noise, like a
simulated gait) with our ``BagWriter``, then measures in separate child processes, so
that each reports its own peak RSS:

* ``ours``: ``read_joint_state_arrays`` (whole-run arrays);
* ``stream``: ``iter_joint_state_blocks`` consumed chunk by chunk (a running sum), to
  show that memory is bounded by a window, not by the bag;
* ``mcap-ros2``: ``mcap.reader.make_reader`` + ``mcap_ros2.decoder.DecoderFactory``
  collecting the same arrays, on the first ``--subset`` messages (it is slow), rate
  extrapolated to the whole bag;
* ``analyze``: the whole ``hexapod analyze`` pipeline (``analyze_bag``: streamed decode,
  frame_id labels, per-cycle indices, online indices, plot series) on a graph-format bag
  of ``--analyze-seconds`` simulated seconds (default 60) written by ``simulate --bag``'s
  writer, every topic of the graph; the rate counts every message in the bag;
* on the same graph bag, reading (and decoding) the four JointState topics analyze uses,
  two ways: ``graph-ours`` (this project's reader, ``iter_joint_state_blocks``) and
  ``graph-mcap`` (the ``mcap`` library's ``SeekingReader.iter_messages``, raw bytes, with
  this project's vectorised decoder on top, batches of 4096 messages per topic): what
  building the reader on the library would cost S6.

Prints medians of ``--repeats`` runs (wall clock and process CPU time), the ratio and
peak RSS. The machine is shared: compare the ratio, not the absolute figures.

Usage:  python scripts/bench_bag_decode.py [--messages 1000000] [--compression zstd]
(with the workspace environment: ``source scripts/env.sh``). About 1-2 min by default.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TOPIC = '/hexapod/joint_states'
NAMES = [f'leg{i}_{j}' for i in range(1, 7) for j in ('hip', 'knee')]


def _peak_rss_mb() -> float:
    """This process's peak resident set (MB): VmHWM, which starts afresh at exec (Linux keeps
    ru_maxrss across exec, so a child would report its parent's peak)."""
    try:
        with open('/proc/self/status') as fh:
            for line in fh:
                if line.startswith('VmHWM:'):
                    return int(line.split()[1]) / 1024  # KiB
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB


def write_bag(path: Path, n: int, compression: str) -> float:
    """Write the benchmark bag; return messages per second."""
    from hexapod_metrics.bag import BagWriter

    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    with BagWriter(path, compression=compression) as writer:
        writer.add_topic(TOPIC, 'sensor_msgs/msg/JointState')
        block = 10_000
        phase = np.arange(12)[None, :]
        for start in range(0, n, block):
            t = (start + np.arange(min(block, n - start)))[:, None] * 1e-3
            noise = rng.standard_normal((3, len(t), 12))
            pos = np.sin(2 * np.pi * t + phase) + 1e-3 * noise[0]
            vel = 2 * np.pi * np.cos(2 * np.pi * t + phase) + 1e-3 * noise[1]
            eff = 5 * np.sin(4 * np.pi * t + phase) + 1e-2 * noise[2]
            for i in range(len(pos)):
                stamp = 1_000_000_000 + (start + i) * 1_000_000
                writer.write_joint_state(TOPIC, stamp, NAMES, pos[i], vel[i], eff[i])
    return n / (time.perf_counter() - t0)


def write_graph_bag(path: Path, seconds: float) -> int:
    """A graph-format bag of a ``seconds`` run at 1 kHz control (PD-P&F, switch to PD-P
    halfway)."""
    from hexapod_control.core.closed_loop import run
    from hexapod_metrics.bag import open_bag
    from hexapod_metrics.core.recording import write_run_bag
    from hexapod_common.core.params import load_params

    p = load_params(**{'sim.dt': 1e-4, 'sim.control_period': 1e-3})  # 1 kHz, as the graph
    write_run_bag(run(p, 'pd_pf', seconds, switches=[(seconds / 2, 'pd_p')]), path)
    with open_bag(path) as bag:
        return bag.message_count


def child(mode: str, bag: Path, subset: int) -> dict[str, float]:
    """Run one measurement in this (child) process."""
    from hexapod_metrics.bag import (
        iter_joint_state_blocks,
        open_bag,
        read_joint_state_arrays,
    )
    from hexapod_metrics.core.analysis import analyze_bag

    rss0 = _peak_rss_mb()
    w0, c0 = time.perf_counter(), time.process_time()
    streams = ['/hexapod/joint_states', '/hexapod/foot_forces', '/hexapod/hip_states',
               '/hexapod/reference']
    if mode == 'graph-ours':
        with open_bag(bag) as opened:
            count = sum(opened.topics[t].message_count for t in streams)
            check = sum(float(b.position[:, 0].sum())
                        for _, b in iter_joint_state_blocks(opened, streams))
    elif mode == 'graph-mcap':
        from hexapod_common.core.cdr import decode_joint_state_batch
        from mcap.reader import make_reader

        batches: dict[str, list[bytes]] = {t: [] for t in streams}
        count, check = 0, 0.0
        with open(next(bag.glob('*.mcap')), 'rb') as fh:
            for _, channel, message in make_reader(fh).iter_messages(topics=streams):
                batch = batches[channel.topic]
                batch.append(message.data)
                if len(batch) == 4096:
                    check += float(decode_joint_state_batch(batch).position[:, 0].sum())
                    count += len(batch)
                    batch.clear()
        for batch in batches.values():
            if batch:
                check += float(decode_joint_state_batch(batch).position[:, 0].sum())
                count += len(batch)
    elif mode == 'analyze':
        with open_bag(bag) as opened:
            count = opened.message_count
        result = analyze_bag(bag)
        check = float(sum(c.sums is not None for c in result.cycles))
    elif mode == 'ours':
        with open_bag(bag) as opened:
            arrays = read_joint_state_arrays(opened, TOPIC)
        count = len(arrays.stamps)
        check = float(arrays.position.sum())
    elif mode == 'stream':
        total = np.zeros(12)
        count = 0
        with open_bag(bag) as opened:
            for _, block in iter_joint_state_blocks(opened, [TOPIC]):
                total += block.position.sum(axis=0)
                count += len(block.stamps)
        check = float(total.sum())
    else:
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory

        pos, vel, eff, stamps = [], [], [], []
        mcap_file = next(bag.glob('*.mcap'))
        with open(mcap_file, 'rb') as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for _, _, _, msg in reader.iter_decoded_messages(topics=[TOPIC]):
                stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
                pos.append(msg.position)
                vel.append(msg.velocity)
                eff.append(msg.effort)
                if len(stamps) >= subset:
                    break
        arrays_p = np.array(pos)
        np.array(vel), np.array(eff), np.array(stamps, np.int64)
        count = len(stamps)
        check = float(arrays_p.sum())
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return {
        'count': count, 'wall': wall, 'cpu': cpu, 'check': check,
        'rss_start_mb': rss0, 'rss_peak_mb': _peak_rss_mb(),
    }


def run_child(mode: str, bag: Path, subset: int) -> dict[str, float]:
    """Measure in a fresh interpreter so that peak RSS belongs to that mode alone."""
    cmd = [sys.executable, __file__, '--child', mode, '--bag', str(bag), '--subset', str(subset)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=os.environ)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _machine() -> str:
    model = ''
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                model = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    load = ', '.join(f'{x:.1f}' for x in os.getloadavg())
    python = platform.python_version()
    return f'{platform.machine()} {model}, {os.cpu_count()} CPUs, load {load}, Python {python}'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--messages', type=int, default=1_000_000)
    parser.add_argument('--subset', type=int, default=50_000, help='messages for mcap-ros2')
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--compression', default='', choices=['zstd', 'lz4', ''],
                        help="chunk compression (default '': none, the writer's default)")
    parser.add_argument('--analyze-seconds', type=float, default=60.0,
                        help='simulated seconds of the graph-format bag for analyze')
    parser.add_argument('--only-analyze', action='store_true',
                        help='measure the analyze pipeline only')
    parser.add_argument('--child', help=argparse.SUPPRESS)
    parser.add_argument('--bag', type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.bag, args.subset)))
        return

    print(f'machine: {_machine()}')
    with tempfile.TemporaryDirectory() as tmp:
        graph_bag = Path(tmp) / 'graph'
        count = write_graph_bag(graph_bag, args.analyze_seconds)
        size = sum(f.stat().st_size for f in graph_bag.iterdir()) / 1e6
        graph: dict[str, list[dict[str, float]]] = {
            'analyze': [], 'graph-ours': [], 'graph-mcap': []}
        for _ in range(args.repeats):  # interleaved, so that load changes hit all alike
            for mode, runs in graph.items():
                runs.append(run_child(mode, graph_bag, 0))
        runs = graph['analyze']
        wall = statistics.median(r['wall'] for r in runs)
        cpu = statistics.median(r['cpu'] for r in runs)
        rss = max(r['rss_peak_mb'] for r in runs)
        base = min(r['rss_start_mb'] for r in runs)
        print(f'   analyze: {count / wall:>12,.0f} msg/s wall, {count / cpu:>12,.0f} msg/s CPU, '
              f'peak RSS {rss:.0f} MB (after imports {base:.0f} MB): {count:,} messages, '
              f'{args.analyze_seconds:g} s graph-format bag, {size:.0f} MB, {wall:.2f} s '
              f'(median of {args.repeats}); S6 target >= 1,000,000 msg/s')
        for mode in ('graph-ours', 'graph-mcap'):
            runs = graph[mode]
            n = runs[0]['count']
            wall = statistics.median(r['wall'] for r in runs)
            cpu = statistics.median(r['cpu'] for r in runs)
            print(f'{mode:>10}: {n / wall:>12,.0f} msg/s wall, {n / cpu:>12,.0f} msg/s CPU, '
                  f'peak RSS {max(r["rss_peak_mb"] for r in runs):.0f} MB: the {n:,} '
                  'JointStates analyze decodes')
        if args.only_analyze:
            return
        bag = Path(tmp) / 'bench'
        rate = write_bag(bag, args.messages, args.compression)
        size = sum(f.stat().st_size for f in bag.iterdir()) / 1e6
        print(f'bag: {args.messages:,} JointState messages, 12 joints, {size:.0f} MB '
              f'(chunk compression {args.compression or "none"!r}), written at {rate:,.0f} msg/s')
        results: dict[str, list[dict[str, float]]] = {'ours': [], 'stream': [], 'mcap-ros2': []}
        for _ in range(args.repeats):  # interleaved, so that load changes hit all alike
            for mode, runs in results.items():
                runs.append(run_child(mode, bag, args.subset))
        rates = {}
        for mode, runs in results.items():
            count = runs[0]['count']
            wall = statistics.median(r['wall'] for r in runs)
            cpu = statistics.median(r['cpu'] for r in runs)
            rss = max(r['rss_peak_mb'] for r in runs)
            base = min(r['rss_start_mb'] for r in runs)
            rates[mode] = count / wall
            note = ''
            if count < args.messages:
                whole = args.messages / rates[mode]
                note = f' (first {count:,} messages; the whole bag would take {whole:.0f} s)'
            print(f'{mode:>10}: {count / wall:>12,.0f} msg/s wall, {count / cpu:>12,.0f} msg/s '
                  f'CPU, peak RSS {rss:.0f} MB (after imports {base:.0f} MB){note}')
        ratio = rates['ours'] / rates['mcap-ros2']
        print(f'ratio ours / mcap-ros2: {ratio:.0f}x (wall, medians of {args.repeats}); '
              'S6 target: >= 1,000,000 msg/s and >= 10x')
        arrays_mb = args.messages * (8 + 3 * 12 * 8) / 1e6
        print(f'whole-run arrays alone take {arrays_mb:.0f} MB; streaming keeps a few chunks '
              f'(~1 MiB each) whatever the bag size')


if __name__ == '__main__':
    main()
