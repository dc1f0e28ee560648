"""Figures in the style of the paper (matplotlib, written as PNG files).

Time plots (Figs. 4-7, 16-17): one curve per controller. Sweep plots (Figs. 8-15): one index
(or a pair, as the paper groups them) against the ground percentage on a log axis.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .core.experiments import SweepResult
from hexapod_metrics.core.indices import INDEX_UNITS

LABELS = {"pd_p": "PD-P", "pd_pf": "PD-P&F", "pd_alpha": "PD^α"}
#: PNG encoding for figures drawn by the dozen (sweeps): zlib level 1 instead of 6, ~10 ms
#: less per figure for files ~15 % larger
PNG_FAST = {"compress_level": 1}
STYLES = {"pd_p": dict(color="tab:blue"), "pd_pf": dict(color="tab:red"),
          "pd_alpha": dict(color="tab:green")}


def _figure(**kw: Any):  # type: ignore[no-untyped-def]
    """A matplotlib ``Figure`` (keywords as for it), drawn by Agg when saved: no pyplot, so no
    global figure list to close and ~20 ms less import in each process that draws."""
    from matplotlib.figure import Figure

    return Figure(**kw)


def label(controller: str) -> str:
    """Display name of a controller segment ('pd_p' -> 'PD-P'; others unchanged)."""
    return LABELS.get(controller, controller)


#: Time signals: key -> (title, y label). Values come from :func:`time_signals`.
TIME_SIGNALS = {
    "dxH": (r"$|\Delta_{1xH}|$", "m"),
    "dyH": (r"$|\Delta_{1yH}|$", "m"),
    "Tm11": (r"$T_{m11}$", "N m"),
    "Tm12": (r"$T_{m12}$", "N m"),
}


def time_signals(obs: np.ndarray, hip_ref: np.ndarray) -> dict[str, np.ndarray]:
    """Leg 1's hip errors and joint torques from samples (N, 9, 6, 2) and refs (N, 6, 2)."""
    from hexapod_common.core.layout import O_HP, O_TQ

    return {"dxH": np.abs(hip_ref[:, 0, 0] - obs[:, O_HP, 0, 0]),
            "dyH": np.abs(hip_ref[:, 0, 1] - obs[:, O_HP, 0, 1]),
            "Tm11": obs[:, O_TQ, 0, 0], "Tm12": obs[:, O_TQ, 0, 1]}


def stick_samples(obs: np.ndarray, t: np.ndarray, frames: int = 3
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The samples :func:`stick_picture` draws of one run's samples (N, 9, 6, 2) at times
    ``t`` (s): ``frames`` of them, spread over the first two thirds of its last gait cycle
    (half the samples). A few kB, where the whole run is tens of MB to send to a worker."""
    n = len(t)
    picks = [n - 1 - (n // 2) + (n // 2) * j // frames for j in range(frames)]
    return obs[picks].copy(), t[picks].copy()


def stick_picture(obs: np.ndarray, t: np.ndarray, l1: float, path: Path, title: str = ""
                  ) -> Path:
    """The robot walking, seen from its left: one panel per sample of ``obs`` (F, 9, 6, 2)
    at times ``t`` (s) (:func:`stick_samples` picks them): hips, knees, feet, the body
    line, ground forces as arrows, in the world frame."""
    from hexapod_metrics.core.figure import FORCE_SCALE, stick_figure

    frames = len(t)
    fig = _figure(figsize=(3.2 * frames, 2.4), dpi=110)
    axes = fig.subplots(1, frames, sharey=True)
    for ax, k in zip(np.atleast_1d(axes), range(frames)):
        f = stick_figure(obs[k], l1)
        for leg in range(f.hip.shape[0]):
            c = "tab:blue" if leg % 2 == 0 else "tab:red"
            ax.plot([f.hip[leg, 0], f.knee[leg, 0], f.foot[leg, 0]],
                    [f.hip[leg, 1], f.knee[leg, 1], f.foot[leg, 1]], "-o", color=c, lw=1.2,
                    ms=2.5, alpha=0.9)
            if f.contact[leg]:
                ax.arrow(f.foot[leg, 0], f.foot[leg, 1], f.force[leg, 0] * FORCE_SCALE,
                         f.force[leg, 1] * FORCE_SCALE, color="tab:green", width=0.01,
                         head_width=0.06, length_includes_head=True)
        order = np.argsort(f.hip[:, 0])
        ax.plot(f.hip[order, 0], f.hip[order, 1], "-", color="k", lw=2.5)
        ax.axhline(0.0, color="0.4", lw=0.8)
        ax.set_aspect("equal")
        ax.set_title(f"t = {t[k]:.2f} s", fontsize=8)
        ax.set_xlabel("x (m)", fontsize=8)
        ax.tick_params(labelsize=7)
    np.atleast_1d(axes)[0].set_ylabel("y (m)", fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    return path


def time_plot(series: Mapping[str, tuple[np.ndarray, np.ndarray]], key: str, path: Path,
              title: str = "", fine: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None
              ) -> Path:
    """One signal vs time, a curve per controller: series[controller] = (t, value);
    ``fine`` (same keys) the same runs at dt/4, drawn dashed on top."""
    name, unit = TIME_SIGNALS[key]
    fig = _figure(figsize=(6.4, 3.4), dpi=110)
    ax = fig.subplots()
    for c, (t, y) in series.items():
        ax.plot(t, y, lw=0.9, label=label(c), **STYLES.get(c, {}))
    for c, (t, y) in (fine or {}).items():
        ax.plot(t, y, lw=0.7, ls="--", color="k" if c not in STYLES else STYLES[c]["color"],
                alpha=0.7, label=f"{label(c)} at dt/4")
    ax.set_xlabel("t (s)")
    ax.set_ylabel(f"{name} ({unit})")
    ax.set_title(title or name)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    return path


@dataclass(frozen=True)
class SweepCurves:
    """What a sweep figure draws of a :class:`SweepResult`: per controller and index, the
    values, the converged flags and the dt band (lowest, highest). A few kB, where the
    result carries every case's parameters: what goes to a worker that draws."""

    values: np.ndarray
    checked: bool
    #: (controller, index name) -> (y, converged, band low, band high), arrays over values
    curves: dict[tuple[str, str], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]

    @classmethod
    def of(cls, res: SweepResult, names: Sequence[str]) -> "SweepCurves":
        """The curves of indices ``names`` of ``res``."""
        return cls(res.values, res.checked,
                   {(c, n): (res.index(c, n), res.converged(c, n), *res.band(c, n))
                    for c in res.outcomes for n in names})

    @property
    def controllers(self) -> list[str]:
        """Controllers in the sweep's order."""
        return list(dict.fromkeys(c for c, _ in self.curves))


def _checked_curve(ax, x: np.ndarray, sc: SweepCurves, c: str, name: str) -> None:  # type: ignore[no-untyped-def]
    """One controller's index over a sweep: line and filled markers where converged, hollow
    markers where not, and the band over dt, dt/2, dt/4 shaded when the sweep was checked."""
    color = STYLES.get(c, {}).get("color", "k")
    y, ok, lo, hi = sc.curves[(c, name)]
    ax.plot(x, y, lw=1.2, color=color, label=label(c))
    ax.plot(x[ok], y[ok], "o", ms=3.5, color=color)
    if sc.checked:
        ax.fill_between(x, lo, hi, color=color, alpha=0.18, lw=0)
        bad = ~ok & ~np.isnan(y)
        if bad.any():
            ax.plot(x[bad], y[bad], "o", ms=6, mfc="white", mec=color,
                    label=f"{label(c)} not dt-converged")
    div = np.isnan(y)
    if div.any():
        ax.plot(x[div], np.zeros(div.sum()), "x", color=color, label=f"{label(c)} diverged")


#: A sweep figure's canvas per layout (panels, log x, x label), kept by each process that
#: draws: the next figure of the same layout clears and reuses its axes, whose tick objects
#: matplotlib then reuses too (most of a figure's time when made anew; the PNG is the same
#: pixel for pixel, tests/test_outputs.py).
_SWEEP_CANVASES: dict[tuple[int, bool, str], Any] = {}


def _sweep_canvas(panels: int, log_x: bool, x_label: str):  # type: ignore[no-untyped-def]
    """(figure, axes row) for a sweep figure of ``panels`` panels, empty: made once per
    layout, then cleared of the previous figure's curves, legends and data limits."""
    key = (panels, log_x, x_label)
    canvas = _SWEEP_CANVASES.get(key)
    if canvas is not None:
        fig, axes = canvas
        for ax in axes:
            for artist in [*ax.lines, *ax.collections]:
                artist.remove()
            if ax.get_legend() is not None:
                ax.get_legend().remove()
            ax.ignore_existing_data_limits = True
            ax.set_autoscale_on(True)
        return fig, axes
    from matplotlib.ticker import FormatStrFormatter

    width = 5.2 * panels  # inches
    fig = _figure(figsize=(width, 3.6), dpi=110)
    axes = list(fig.subplots(1, panels, squeeze=False)[0])
    for ax in axes:
        if log_x:
            ax.set_xscale("log")
            # plain numbers (10, 100, 1000 %): no mathtext to lay out, ~10 ms a figure
            ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.set_xlabel(x_label)
        ax.grid(alpha=0.3, which="both")
    # fixed margins (room for 7-character tick labels) rather than tight_layout, whose
    # extra text-measuring pass was a quarter of a sweep figure's time
    fig.subplots_adjust(left=0.8 / width, right=1.0 - 0.15 / width, bottom=0.15, top=0.88,
                        wspace=0.35)
    _SWEEP_CANVASES[key] = (fig, axes)
    return fig, axes


def sweep_plot(res: SweepResult | SweepCurves, names: Sequence[str], path: Path, title: str,
               x_scale: float = 100.0, x_label: str = "% of base ground (K_x, K_y, B_x, B_y)",
               log_x: bool = True) -> Path:
    """Indices ``names`` vs the swept value (times ``x_scale``), both controllers; with a
    checked sweep, the dt-convergence band shaded and unconverged points hollow."""
    sc = res if isinstance(res, SweepCurves) else SweepCurves.of(res, names)
    fig, axes = _sweep_canvas(len(names), log_x, x_label)
    x = sc.values * x_scale
    for ax, name in zip(axes, names):
        for c in sc.controllers:
            _checked_curve(ax, x, sc, c, name)
        shown = "P_L (= F_L)" if name == "F_L" else name
        ax.set_ylabel(f"{shown} ({INDEX_UNITS[name]})")
        ax.legend(fontsize=8)
    fig.suptitle(title + ("" if sc.checked else " (not checked for dt convergence)"))
    fig.savefig(path, pil_kwargs=PNG_FAST)
    return path


#: One sweep figure to draw: (result, index names, output path, title, sweep_plot keywords).
SweepFigure = tuple[SweepResult, Sequence[str], Path, str, dict[str, Any]]


def sweep_plots(figures: Sequence[SweepFigure], backend: Any = None) -> list[Path]:
    """Draw sweep figures (:func:`sweep_plot`) through a :class:`Drawer`: on the local worker
    processes of ``backend`` when it has them (idle once the runs are done: the figures then
    take half the wall time on two cores), else here."""
    drawer = Drawer(backend)
    for res, names, path, title, kw in figures:
        drawer.sweep(res, names, path, title, **kw)
    drawer.wait()
    return [Path(path) for _, _, path, _, _ in figures]


def _draw_job(job: tuple[Callable[..., Any], tuple[Any, ...], dict[str, Any]]) -> Any:
    fn, args, kw = job
    return fn(*args, **kw)


class Drawer:
    """Draws figures (``draw(plot_function, *args, **kw)``) on the local worker processes of
    a backend while the caller goes on: they queue between its chunks of runs instead of
    keeping the command's process busy while the workers wait. Without local workers
    (inline, Dask: a remote worker's file would not be here) it draws at once. :meth:`wait`
    returns once every figure is written and raises the first failure."""

    def __init__(self, backend: Any = None) -> None:
        from .core.parallel import local_submit

        self._submit = local_submit(backend)
        self._pending: list[Any] = []

    def draw(self, fn: Callable[..., Any], *args: Any, **kw: Any) -> None:
        """``fn(*args, **kw)``, here or on a worker (arguments must pickle: prefer
        :class:`SweepCurves` to a whole :class:`SweepResult`)."""
        if self._submit is None:
            fn(*args, **kw)
        else:
            self._pending.append(self._submit(_draw_job, (fn, args, kw)))

    def sweep(self, res: SweepResult, names: Sequence[str], path: Path, title: str,
              **kw: Any) -> None:
        """:func:`sweep_plot` of ``res`` through :meth:`draw`, sending its curves (a few kB),
        not the whole result."""
        self.draw(sweep_plot, SweepCurves.of(res, names), names, path, title, **kw)

    def wait(self) -> None:
        """Every figure drawn so far is written (the first failure raised)."""
        pending, self._pending = self._pending, []
        for fut in pending:
            fut.result()


def rate_plot(sweeps: Mapping[float, SweepResult | SweepCurves], name: str, path: Path,
              title: str) -> Path:
    """E6: one index against the control rate (Hz, log axis), one panel per ground.

    ``sweeps[rate]`` are checked ground sweeps that share their ground values (or their
    :class:`SweepCurves` of ``name``).
    """
    cur = {r: s if isinstance(s, SweepCurves) else SweepCurves.of(s, (name,))
           for r, s in sweeps.items()}
    rates = np.array(sorted(cur))
    first = next(iter(cur.values()))
    values = first.values
    cols = 3
    rows = -(-len(values) // cols)
    fig = _figure(figsize=(4.0 * cols, 2.8 * rows), dpi=100)
    axes = fig.subplots(rows, cols, squeeze=False, sharex=True)
    for k, v in enumerate(values):
        ax = axes[k // cols][k % cols]
        for c in first.controllers:
            color = STYLES.get(c, {}).get("color", "k")
            y, ok, lo, hi = (np.array([cur[r].curves[(c, name)][j][k] for r in rates])
                             for j in range(4))
            ok = ok.astype(bool)
            ax.plot(rates, y, lw=1.1, color=color, label=label(c))
            ax.fill_between(rates, lo, hi, color=color, alpha=0.18, lw=0)
            ax.plot(rates[ok], y[ok], "o", ms=3.5, color=color)
            bad = ~ok & ~np.isnan(y)
            ax.plot(rates[bad], y[bad], "o", ms=6, mfc="white", mec=color)
        ax.set_xscale("log")
        ax.set_title(f"ground {100 * v:.3g} %", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        if k % cols == 0:
            ax.set_ylabel(f"{name} ({INDEX_UNITS[name]})")
        if k // cols == rows - 1:
            ax.set_xlabel("control rate (Hz)")
    for k in range(len(values), rows * cols):
        axes[k // cols][k % cols].axis("off")
    axes[0][0].legend(fontsize=7, title="hollow: not dt-converged", title_fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path)
    return path


#: Cell codes of :func:`advantage_map`.
MAP_CODES = {"pd_pf better": 2, "undecided": 1, "pd_p better": 0}


def advantage_map(rates: Sequence[float], percents: Sequence[float],
                  cells: Mapping[tuple[float, float], str],
                  converged: Mapping[tuple[float, float], bool], path: Path,
                  title: str) -> Path:
    """E6: a (control rate, ground) map: where PD-P&F's tracking errors are all below
    PD-P's (decided), where PD-P's are (at least one, decided), where it is undecided; cells
    with an unconverged number are hatched."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch, Rectangle

    grid = np.array([[MAP_CODES[cells[(r, g)]] for g in percents] for r in rates], float)
    fig = _figure(figsize=(1.0 + 0.7 * len(percents), 1.2 + 0.55 * len(rates)), dpi=110)
    ax = fig.subplots()
    cmap = ListedColormap(["tab:blue", "lightgrey", "tab:red"])
    ax.imshow(grid, cmap=cmap, vmin=0, vmax=2, aspect="auto", origin="lower")
    for i, r in enumerate(rates):
        for j, g in enumerate(percents):
            if not converged[(r, g)]:
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="///",
                                       lw=0, color="k"))
    ax.set_xticks(range(len(percents)), [f"{g:g}" for g in percents])
    ax.set_yticks(range(len(rates)), [f"{r / 1000:g}" for r in rates])
    ax.set_xlabel("ground (% of base)")
    ax.set_ylabel("control rate (kHz)")
    ax.set_title(title, fontsize=10)
    ax.legend(handles=[Patch(color="tab:red", label="PD-P&F below PD-P (all 4 errors)"),
                       Patch(color="tab:blue", label="PD-P below on some error"),
                       Patch(color="lightgrey", label="undecided (within bands)"),
                       Patch(fill=False, hatch="///", label="a deciding number not dt-converged")],
              fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    # the canvas grows to hold the legend beside the map (tight_layout could not make room
    # for it on a small map: the legend and the y label were cut off)
    fig.savefig(path, bbox_inches="tight")
    return path


__all__ = ["LABELS", "MAP_CODES", "TIME_SIGNALS", "advantage_map", "label", "rate_plot",
           "stick_picture", "stick_samples", "sweep_plot", "time_plot", "time_signals"]
