"""`hexapod animate BAG`: the stick-figure hexapod walking, one panel per controller segment.

Frames are taken from the bag at ``fps`` of simulated time while streaming it (only the frame
samples are kept), drawn with matplotlib and written as GIF (Pillow) or MP4 (if ffmpeg is
available).
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexapod_common.core import topics as T

from hexapod_metrics.core.analysis import label_ticks, controller_changes
from hexapod_metrics.core.bag_params import bag_params
from hexapod_metrics.bag import iter_joint_state_blocks, open_bag
from hexapod_metrics.bag import BagReadError
from hexapod_metrics.core.figure import FORCE_SCALE, stick_figure
from .plots import label

STATE = (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES)


@dataclass(frozen=True)
class Segment:
    """Frames of one controller segment: times (n,) and observations (n, 9, 6, 2)."""

    controller: str
    t: np.ndarray
    obs: np.ndarray


def load_frames(path: str | Path, fps: float = 30.0) -> tuple[list[Segment], float, bool]:
    """Frame samples of every controller segment, the thigh length, and whether truncated."""
    with open_bag(path) as bag:
        missing = [t for t in STATE if t not in bag.topics]
        if missing:
            raise BagReadError(f"{path}: not a hexapod bag (no {', '.join(missing)})")
        p = bag_params(bag).params
        dt_ns = int(round(p.sim.control_period * 1e9))
        stride = max(1, int(round(1.0 / (fps * p.sim.control_period))))
        kept: dict[str, dict[int, np.ndarray]] = {t: {} for t in STATE}
        for topic, arr in iter_joint_state_blocks(bag, STATE):
            k = np.rint(arr.stamps / dt_ns).astype(np.int64)
            for j in np.flatnonzero(k % stride == 0):
                kept[topic][int(k[j])] = np.stack([arr.position[j], arr.velocity[j],
                                                   arr.effort[j]])
        changes = controller_changes(bag, dt_ns)
        truncated = bag.truncated
    ticks = sorted(set.intersection(*(set(v) for v in kept.values())))
    if not ticks:
        raise BagReadError(f"{path}: no complete sample to draw")
    cols = {t: tuple(np.array([kept[t][k][r] for k in ticks]) for r in range(3)) for t in STATE}
    obs = T.obs_from_columns(cols)
    ks = np.array(ticks)
    labels = label_ticks(changes, ks)
    segments = []
    start = 0
    for j in range(1, len(ks) + 1):
        if j == len(ks) or labels[j] != labels[start]:
            segments.append(Segment(str(labels[start]), ks[start:j] * p.sim.control_period,
                                    obs[start:j]))
            start = j
    return segments, p.robot.leg_length_1, truncated


def animate(segments: list[Segment], l1: float, out: Path, fps: float = 30.0,
            title: str = "") -> Path:
    """Draw and write the animation; GIF unless ``out`` ends in .mp4."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter

    n = len(segments)
    fig, axes = plt.subplots(1, n, figsize=(5.0 * n, 3.6), dpi=80, squeeze=False)
    axes = axes[0]
    artists = []
    for ax, seg in zip(axes, segments):
        ax.set_aspect("equal")
        ax.set_ylim(-0.4, 2.4)
        ax.axhline(0.0, color="saddlebrown", lw=1.5)
        ax.axhspan(-0.4, 0.0, color="tan", alpha=0.4)
        ax.set_xlabel("x (m)")
        left = [ax.plot([], [], "-o", color="tab:blue", lw=2, ms=3)[0] for _ in range(3)]
        right = [ax.plot([], [], "--o", color="tab:orange", lw=1.5, ms=3, alpha=0.8)[0]
                 for _ in range(3)]
        body = ax.plot([], [], "-", color="k", lw=3)[0]
        feet = ax.plot([], [], "o", color="red", ms=6)[0]
        arrows = [ax.annotate("", xy=(0, 0), xytext=(0, 0), arrowprops=dict(
            arrowstyle="->", color="red", lw=1.2)) for _ in range(6)]
        text = ax.text(0.02, 0.95, "", transform=ax.transAxes, va="top", fontsize=9)
        ax.set_title(label(seg.controller))
        artists.append((left, right, body, feet, arrows, text))
    frames = max(len(s.t) for s in segments)

    def draw(i: int):  # type: ignore[no-untyped-def]
        out_artists = []
        for ax, seg, (left, right, body, feet, arrows, text) in zip(axes, segments, artists):
            j = min(i, len(seg.t) - 1)
            f = stick_figure(seg.obs[j], l1)
            cx = float(f.hip[:, 0].mean())
            ax.set_xlim(cx - 2.5, cx + 2.5)
            for leg in range(6):
                line = (left if leg % 2 == 0 else right)[leg // 2]
                line.set_data([f.hip[leg, 0], f.knee[leg, 0], f.foot[leg, 0]],
                              [f.hip[leg, 1], f.knee[leg, 1], f.foot[leg, 1]])
                start = f.foot[leg]
                end = start + (f.force[leg] * FORCE_SCALE if f.contact[leg] else 0.0)
                arrows[leg].set_position(start)
                arrows[leg].xy = end
                arrows[leg].set_visible(bool(f.contact[leg]))
            order = [0, 2, 4]
            body.set_data(f.hip[order, 0], f.hip[order, 1])
            feet.set_data(f.foot[f.contact, 0], f.foot[f.contact, 1])
            text.set_text(f"t = {seg.t[j]:.2f} s")
            out_artists += [*left, *right, body, feet, *arrows, text]
        return out_artists

    if title:
        fig.suptitle(title)
    fig.tight_layout()
    anim = FuncAnimation(fig, draw, frames=frames, interval=1000.0 / fps, blit=False)
    if out.suffix.lower() == ".mp4":
        writer = FFMpegWriter(fps=fps)
    else:
        writer = PillowWriter(fps=fps)
    anim.save(str(out), writer=writer)
    plt.close(fig)
    return out


def _cmd_animate(args: argparse.Namespace) -> int:
    segments, l1, truncated = load_frames(args.bag, args.fps)
    from .cmd_analyze import beside

    out = Path(args.out) if args.out else beside(args.bag, ".gif")
    if out.suffix.lower() == ".mp4":
        from matplotlib.animation import FFMpegWriter

        if not FFMpegWriter.isAvailable():
            raise OSError("MP4 needs ffmpeg on PATH; write a .gif instead")
    note = " (bag truncated: drawing its readable part)" if truncated else ""
    animate(segments, l1, out, args.fps, f"{Path(args.bag).name}{note}")
    print(f"{sum(len(s.t) for s in segments)} frames, {len(segments)} segment(s): {out}{note}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register `animate`."""
    ap = sub.add_parser("animate", help="GIF/MP4 of the stick-figure hexapod from a bag")
    ap.add_argument("bag", metavar="BAG")
    ap.add_argument("--out", help="output file (.gif or .mp4; default: beside the bag, BAG.gif)")
    ap.add_argument("--fps", type=float, default=30.0, help="frames per simulated second")
    ap.set_defaults(func=_cmd_animate)


__all__ = ["Segment", "add_parser", "animate", "load_frames"]
