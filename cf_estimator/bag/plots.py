"""PNG plots of a replay (matplotlib, Agg backend: no display needed).

* ``attitude.png`` — roll, pitch, yaw [deg] of the estimate, and of the reference when there is one;
* ``error.png`` — total / inclination / heading error [deg] against the reference (with one);
* ``clipping.png`` — saturation (clip) activity: the accelerometer error |e| and the fraction of
  samples clipped per second;
* ``bias.png`` — the gyro-bias estimate ± its standard deviation [deg/s] per sensor axis, and
  the filter's still phases (where the bias is measured from the gyro).

Time axes are seconds since the first output's header stamp. Files are written through a
temporary sibling and renamed, so a failure never leaves a half-written PNG.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cf_estimator.core import quaternion as quat


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> Path:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.partial-", suffix=".png", dir=path.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=110, format="png")
        from cf_estimator.bag.io import user_file_mode

        os.chmod(tmp, user_file_mode())  # mkstemp made it 0600
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    finally:
        _pyplot().close(fig)
    return path


def _shade(ax: Any, windows: Sequence[tuple[float, float, str]], t0: float) -> None:
    for start, end, label in windows:
        ax.axvspan(start - t0, end - t0, color="0.85", zorder=0)
        ax.text((start + end) / 2 - t0, 1.0, label, transform=ax.get_xaxis_transform(),
                ha="center", va="bottom", fontsize=7, color="0.4")


def alignment_label(alignment: str | None) -> str:
    """Legend suffix of the estimate against a reference: what the console reports too
    (``none``: the raw estimate; ``first``/``mean``: heading-aligned that way)."""
    if alignment in (None, "none"):
        return ""
    return f" (heading-aligned: {alignment})"


def plot_replay(
    result: Any, directory: str | Path, *, title: str = "",
    windows: Sequence[tuple[float, float, str]] = (),
) -> list[Path]:
    """Write the replay plots into ``directory`` (created if missing); returns the paths.

    ``windows``: (start_s, end_s, label) in header-stamp seconds to shade (disturbances).
    """
    plt = _pyplot()
    out_dir = Path(directory)
    out_dir.mkdir(parents=True, exist_ok=True)
    s = result.series
    if s.t_s.size == 0:
        return []
    t0 = float(s.t_s[0])
    t = s.t_s - t0
    written: list[Path] = []
    names = ("roll", "pitch", "yaw")
    scored = result.scored or {}
    suffix = f" — {title}" if title else ""

    fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    ref_rpy = None
    if scored:
        ref_rpy = np.degrees(quat.to_euler(scored["q_ref"]))
        est_rpy = np.degrees(quat.to_euler(scored["q_est_aligned"]))
    offline = s.online_rpy_rad.shape[0] == t.size  # an offline replay: show the online too
    kind = "offline estimate" if offline else "estimate"
    ref_info = result.summary.get("reference") or {}
    aligned = alignment_label(ref_info.get("heading_alignment"))
    autopilot = ref_info.get("kind") == "autopilot"  # a PX4 log: the autopilot's own estimate
    ref_label = "autopilot (vehicle_attitude)" if autopilot else "reference"
    versus = (" vs the autopilot's estimate (agreement, not ground truth)" if autopilot
              else " vs reference")
    for i, ax in enumerate(axes):
        if ref_rpy is not None:
            tr = scored["t_s"] - t0
            ax.plot(tr, ref_rpy[:, i], color="k", lw=1.0, label=ref_label)
            ax.plot(tr, est_rpy[:, i], color="C0", lw=0.8, label=f"{kind}{aligned}")
        else:
            ax.plot(t, np.degrees(s.rpy_rad[:, i]), color="C0", lw=0.8, label=kind)
        if offline:
            ax.plot(t, np.degrees(s.online_rpy_rad[:, i]), color="C3", lw=0.7, ls="--",
                    label="online filter")
        ax.set_ylabel(f"{names[i]} [deg]")
        ax.grid(alpha=0.3)
        _shade(ax, windows, t0)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle("Attitude" + (versus if autopilot else "") + suffix)
    fig.tight_layout()
    written.append(_save(fig, out_dir / "attitude.png"))

    if scored:
        fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
        tr = scored["t_s"] - t0
        for key, color in (("total", "k"), ("inclination", "C0"), ("heading", "C1")):
            axes[0].plot(tr, np.degrees(scored[key]), lw=0.8, color=color, label=key)
        if not offline and not autopilot and s.tilt_var_rad2.size == t.size:
            # the published covariance's tilt σ: an honest one is the inclination error's RMS
            # (issue 27; the summary's "covariance" line scores it)
            axes[0].plot(t, np.degrees(np.sqrt(s.tilt_var_rad2)), lw=0.8, color="C0", ls="--",
                         label="reported tilt σ, √(cov[0]+cov[4])")
        axes[0].set_ylabel("error [deg]")
        axes[0].legend(loc="upper right", fontsize=8)
        for i, name in enumerate(names):
            axes[1].plot(tr, np.degrees(scored[name]) * 60.0, lw=0.8, color=f"C{i}", label=name)
        axes[1].set_ylabel("Euler error [arcmin]")
        axes[1].legend(loc="upper right", fontsize=8)
        for ax in axes:
            ax.grid(alpha=0.3)
            _shade(ax, windows, t0)
        axes[-1].set_xlabel("time [s]")
        fig.suptitle(("Difference" if autopilot else "Error") + versus + suffix)
        fig.tight_layout()
        written.append(_save(fig, out_dir / "error.png"))

    if s.clipped.size == t.size and s.error_norm_rad.size == t.size:
        fig, axes = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
        axes[0].plot(t, np.degrees(s.error_norm_rad), lw=0.6, color="C0")
        axes[0].set_ylabel("|e| [deg]")
        axes[0].set_yscale("symlog", linthresh=0.1)
        edges = np.arange(0.0, max(t[-1], 1.0) + 1.0, 1.0)
        idx = np.clip(np.digitize(t, edges) - 1, 0, edges.size - 2)
        counts = np.bincount(idx, minlength=edges.size - 1)
        clipped = np.bincount(idx, weights=s.clipped.astype(float), minlength=edges.size - 1)
        frac = np.divide(clipped, counts, out=np.zeros_like(clipped), where=counts > 0)
        axes[1].step(edges[:-1], frac * 100.0, where="post", color="C3")
        axes[1].set_ylabel("clipped [% per s]")
        axes[1].set_ylim(-2, 102)
        for ax in axes:
            ax.grid(alpha=0.3)
            _shade(ax, windows, t0)
        axes[-1].set_xlabel("time [s]")
        fig.suptitle("Saturation (clip) activity" + suffix)
        fig.tight_layout()
        written.append(_save(fig, out_dir / "clipping.png"))

    if s.gyro_bias_rad_s.shape[0] > 0:
        fig, ax = plt.subplots(figsize=(10, 3.5))
        bt = s.bias_t_s - t0
        sigma = np.degrees(s.gyro_bias_sigma_rad_s)
        for i, axis in enumerate("xyz"):
            b = np.degrees(s.gyro_bias_rad_s[:, i])
            ax.plot(bt, b, lw=0.9, label=f"b_{axis}")
            ax.fill_between(bt, b - sigma, b + sigma, alpha=0.15, lw=0)
        still = s.at_rest.astype(float)
        if still.any():  # the filter's still phases, where the bias is measured from the gyro
            ax.fill_between(s.t_s - t0, 0, 1, where=still > 0, color="0.6", alpha=0.25, lw=0,
                            step="post", transform=ax.get_xaxis_transform(), label="still")
        b_all = np.degrees(s.gyro_bias_rad_s)
        pad = max(0.1, 0.25 * float(np.ptp(b_all)))  # the prior's wide band would hide the bias
        ax.set_ylim(float(b_all.min()) - pad, float(b_all.max()) + pad)
        ax.set_ylabel("gyro bias ± 1σ [deg/s]")
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
        _shade(ax, windows, t0)
        fig.suptitle("Gyro-bias estimate" + suffix)
        fig.tight_layout()
        written.append(_save(fig, out_dir / "bias.png"))
    return written
