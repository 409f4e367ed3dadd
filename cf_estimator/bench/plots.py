"""PNG plots of bench results (matplotlib, Agg backend; imported only when plotting)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np


def plot_broad_per_trial(doc: Mapping, out_png: str, algorithms: Sequence[str] | None = None,
                         title: str = "BROAD: RMSE per trial") -> None:
    """Two bar panels per trial: 9-D total RMSE and 6-D inclination RMSE, one bar per algorithm."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    trials = list(doc["trials"])
    bases = algorithms or sorted({a.rsplit("_", 1)[0] for t in trials for a in doc["trials"][t]},
                                 key=lambda b: (b != "cf_estimator", b))
    fig, axes = plt.subplots(2, 1, figsize=(13, 7.5), sharex=True)
    x = np.arange(len(trials))
    width = 0.8 / max(len(bases), 1)
    for ax, (suffix, metric, label) in zip(axes, (
            ("9d", "total_rmse_deg", "9-D total RMSE [deg]"),
            ("6d", "inclination_rmse_deg", "6-D inclination RMSE [deg]")), strict=True):
        for k, b in enumerate(bases):
            vals = [doc["trials"][t].get(f"{b}_{suffix}", {}).get(metric) for t in trials]
            vals = [np.nan if v is None else v for v in vals]
            ax.bar(x + (k - (len(bases) - 1) / 2) * width, vals, width, label=b)
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(ncol=len(bases), fontsize=9)
    axes[0].set_title(title)
    axes[1].set_xticks(x, [t.replace("_", " ", 1)[:28] for t in trials], rotation=60, ha="right",
                       fontsize=8)
    fig.tight_layout()
    fig.savefig(out_png, dpi=90)
    plt.close(fig)


def plot_tilt_series(series: Mapping[str, tuple[np.ndarray, np.ndarray]], windows, out_png: str,
                     title: str) -> None:
    """Tilt error [arcmin] over time for several estimators, disturbance windows shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11, 4.5))
    for start, end, label in windows:
        ax.axvspan(start, end, color="0.9")
        ax.text(start, 1.0, label, transform=ax.get_xaxis_transform(), va="top", fontsize=8)
    for name, (t, e) in series.items():
        ax.plot(t, e, lw=0.8, label=name)
    ax.axhline(90.0, color="r", ls="--", lw=0.8, label="thesis limit 90'")
    ax.set_yscale("log")
    ax.set_ylim(0.1, None)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("tilt error [arcmin]")
    ax.set_title(title)
    ax.legend(fontsize=8, ncol=3)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=90)
    plt.close(fig)
