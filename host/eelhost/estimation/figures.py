"""Figures of estimation and validation, like the paper's figures 6-9, 12 and 13."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from eelhost.estimation.optimise import FitResult  # noqa: E402
from eelhost.estimation.validate import ValidationRun  # noqa: E402
from eelhost.plots import (  # noqa: E402
    draw_current,
    draw_waypoints,
    label_axes,
    plot_track_errors,
    save_figure,
)


def plot_fitness_history(fits: dict[str, FitResult], path: str | Path) -> Path:
    """Best fitness against generation for each fit (paper figure 6), log scale."""
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    for motion, res in fits.items():
        gens = [h[0] for h in res.history]
        best = [h[1] for h in res.history]
        ax.plot(gens, best, label=f"{motion} ({res.method})")
    ax.set_yscale("log")
    ax.set_xlabel("generation")
    ax.set_ylabel("best fitness (minimax error)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), fontsize=9)  # below: off the curves
    return _save(fig, path)


def plot_paths(runs: Sequence[ValidationRun], path: str | Path, title: str = "") -> Path:
    """Experiment against simulation, one small panel per experiment (paper figures 7, 8, 12)."""
    n = len(runs)
    cols = min(4, n)
    rows = int(np.ceil(n / cols))
    # a few panels get room (two paths: 10 x 4.2 in, 1500 x 630 px at 150 dpi); many, less each
    width, height = (5.0, 4.2) if n <= 2 else (3.6, 3.0)
    fig, axes = plt.subplots(
        rows, cols, figsize=(width * cols, height * rows + 0.4), squeeze=False,
        constrained_layout=True,
    )
    for ax, run in zip(axes.flat, runs, strict=False):
        e = run.experiment
        ax.plot(e.position_m[:, 0], e.position_m[:, 1], color="k", lw=1, label="experiment")
        ax.plot(
            run.sim_positions_m[:, 0],
            run.sim_positions_m[:, 1],
            "--",
            color="tab:red",
            lw=1.2,
            label="simulation",
        )
        draw_waypoints(ax, e.scenario.waypoints_m, e.scenario.acceptance_radius_m)
        draw_current(
            ax, e.scenario.current_speed_m_s, e.scenario.current_direction_deg, at=(0.55, 0.12)
        )
        ax.set_title(f"{e.name}\nE_x {run.row.Ex_mean_BL:.3f} BL", fontsize=9)
        ax.set_aspect("equal", adjustable="datalim")
        ax.tick_params(labelsize=8)
        label_axes(ax)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def plot_time_series(run: ValidationRun, path: str | Path) -> Path:
    """x(t), y(t) and heading(t) of experiment and simulation (paper figures 9 and 13)."""
    e = run.experiment
    fig, axes = plt.subplots(3, 1, figsize=(6, 6), sharex=True, constrained_layout=True)
    series = [
        (e.position_m[:, 0], run.sim_positions_m[:, 0], "x (m)"),
        (e.position_m[:, 1], run.sim_positions_m[:, 1], "y (m)"),
    ]
    for ax, (ye, ys, label) in zip(axes[:2], series, strict=True):
        ax.plot(e.t_s, ye, color="k", lw=1, label="experiment")
        ax.plot(run.times_s, ys, "--", color="tab:red", label="simulation")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    if e.heading_rad is not None:
        axes[2].plot(e.t_s, np.degrees(np.unwrap(e.heading_rad)), color="k", lw=1)
    axes[2].plot(run.times_s, np.degrees(np.unwrap(run.sim_heading_rad)), "--", color="tab:red")
    axes[2].set_ylabel("heading (deg)")
    axes[2].set_xlabel("t (s)")
    axes[2].grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[0].set_title(e.name)
    return _save(fig, path)


def plot_validation(runs: Sequence[ValidationRun], out: str | Path) -> list[Path]:
    """The figures of a validation in folder ``out``: one per motion, a time series per path.

    Straight runs as along- and cross-track error against time next to their tracks (every
    straight track looks alike at tank scale); turning runs and paths as experiment against
    simulation in the plane; each path also as x(t), y(t), heading(t).
    """
    folder = Path(out)
    written = []
    for motion in ("straight", "turning", "path"):
        group = [r for r in runs if r.experiment.motion == motion]
        if motion == "straight" and group:
            title = "straight runs: the twin against the recordings"
            written.append(plot_track_errors(group, folder / "paths_straight.png", title))
        elif group:
            title = f"{motion}: experiment (black) and twin (red)"
            written.append(plot_paths(group, folder / f"paths_{motion}.png", title))
    for r in runs:
        if r.experiment.motion == "path":
            written.append(plot_time_series(r, folder / f"timeseries_{r.experiment.name}.png"))
    return written


def _save(fig: plt.Figure, path: str | Path) -> Path:
    return save_figure(fig, path)  # at the print resolution (eelhost.plots.PRINT_DPI)
