"""Figures in the style of the paper (matplotlib, written as PNG files).

Time plots (Figs. 4-7, 16-17): one curve per controller. Sweep plots (Figs. 8-15): one index
(or a pair, as the paper groups them) against the ground percentage on a log axis.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .core.experiments import SweepResult
from .core.indices import INDEX_UNITS

LABELS = {"pd_p": "PD-P", "pd_pf": "PD-P&F"}
STYLES = {"pd_p": dict(color="tab:blue"), "pd_pf": dict(color="tab:red")}


def _pyplot():  # type: ignore[no-untyped-def]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


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
    from hexapod_sim.core.layout import O_HP, O_TQ

    return {"dxH": np.abs(hip_ref[:, 0, 0] - obs[:, O_HP, 0, 0]),
            "dyH": np.abs(hip_ref[:, 0, 1] - obs[:, O_HP, 0, 1]),
            "Tm11": obs[:, O_TQ, 0, 0], "Tm12": obs[:, O_TQ, 0, 1]}


def time_plot(series: Mapping[str, tuple[np.ndarray, np.ndarray]], key: str, path: Path,
              title: str = "") -> Path:
    """One signal vs time, a curve per controller: series[controller] = (t, value)."""
    plt = _pyplot()
    name, unit = TIME_SIGNALS[key]
    fig, ax = plt.subplots(figsize=(6.4, 3.4), dpi=110)
    for c, (t, y) in series.items():
        ax.plot(t, y, lw=0.9, label=label(c), **STYLES.get(c, {}))
    ax.set_xlabel("t (s)")
    ax.set_ylabel(f"{name} ({unit})")
    ax.set_title(title or name)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def sweep_plot(res: SweepResult, names: Sequence[str], path: Path, title: str,
               x_scale: float = 100.0, x_label: str = "% of base ground (K_x, K_y, B_x, B_y)",
               log_x: bool = True) -> Path:
    """Indices ``names`` vs the swept value (times ``x_scale``), both controllers."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(names), figsize=(5.2 * len(names), 3.6), dpi=110,
                             squeeze=False)
    x = res.values * x_scale
    for ax, name in zip(axes[0], names):
        for c in res.outcomes:
            y = res.index(c, name)
            ax.plot(x, y, marker="o", ms=3, lw=1.2, label=label(c), **STYLES.get(c, {}))
            bad = np.isnan(y)
            if bad.any():
                ax.plot(x[bad], np.zeros(bad.sum()), "x", color=STYLES.get(c, {}).get(
                    "color", "k"), label=f"{label(c)} diverged")
        if log_x:
            ax.set_xscale("log")
        shown = "P_L (= F_L)" if name == "F_L" else name
        ax.set_ylabel(f"{shown} ({INDEX_UNITS[name]})")
        ax.set_xlabel(x_label)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


__all__ = ["LABELS", "TIME_SIGNALS", "label", "sweep_plot", "time_plot", "time_signals"]
