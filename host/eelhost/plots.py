"""Figures of runs, and the pieces every figure of eelbot draws the same way.

:func:`plot_run`: the path with the robot drawn at intervals, and x(t), y(t), heading(t), like the
paper's figure 9; :func:`plot_track_errors`: straight runs as the twin's along-track and
cross-track error against time next to the tracks. The shared pieces: waypoints with their
acceptance circles (:func:`draw_waypoints`), a labelled current arrow (:func:`draw_current`), axis
labels with units (:func:`label_axes`), a legend without duplicate entries
(:func:`legend_once`). Uses matplotlib's non-interactive Agg backend (no screen needed).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import animation  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402
from scipy.ndimage import uniform_filter1d  # noqa: E402

from eelhost.files import atomic_writer, default_file_mode  # noqa: E402
from eelsim.closed_loop import RunResult  # noqa: E402
from eelsim.dynamics import link_positions  # noqa: E402
from eelsim.model import SwimmerModel  # noqa: E402
from eelsim.scenario import Scenario  # noqa: E402


def robot_outline(model: SwimmerModel, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polyline through the joints of the robot, tail tip to head tip, (x, y)."""
    n = model.n_links
    X, Y = link_positions(model, state)
    th = state[:n]
    lh = model.half_length_m
    xs = np.concatenate([[X[0] - lh[0] * np.cos(th[0])], X + lh * np.cos(th)])
    ys = np.concatenate([[Y[0] - lh[0] * np.sin(th[0])], Y + lh * np.sin(th)])
    return xs, ys


def label_axes(ax: plt.Axes, x: str = "x (m)", y: str = "y (m)") -> None:
    """Label both axes, with their units."""
    ax.set_xlabel(x)
    ax.set_ylabel(y)


def legend_once(ax: plt.Axes, **kwargs: Any) -> None:
    """A legend with each label once (artists drawn in a loop share one), none if no labels."""
    entries: dict[str, Any] = {}
    for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
        if label and not label.startswith("_"):
            entries.setdefault(label, handle)
    if entries:
        ax.legend(list(entries.values()), list(entries), **kwargs)


def draw_waypoints(
    ax: plt.Axes,
    waypoints_m: Sequence[Sequence[float]],
    radius_m: float,
    colour: str = "tab:green",
    numbered: bool = True,
) -> None:
    """Waypoints as crosses with their acceptance circles (labelled once for the legend)."""
    for i, (wx, wy) in enumerate(np.asarray(waypoints_m, dtype=float)):
        ax.add_patch(
            Circle(
                (wx, wy),
                radius_m,
                fill=False,
                ls="--",
                color=colour,
                label=f"acceptance radius {radius_m:g} m" if i == 0 else None,
            )
        )
        ax.plot(wx, wy, "x", color=colour, label="waypoints" if i == 0 else None)
        if numbered:
            ax.annotate(
                f"W{i + 1}", (wx, wy), textcoords="offset points", xytext=(4, 4), fontsize=8
            )


def draw_current(
    ax: plt.Axes,
    speed_m_s: float,
    direction_deg: float,
    colour: str = "tab:blue",
    at: tuple[float, float] = (0.1, 0.9),
) -> None:
    """An arrow for the current, in a corner of the axes, labelled with speed and direction.

    The arrow is drawn in points from a point given in axes fractions, so its direction is
    true whatever the axes' scale; nothing is drawn without a current.
    """
    if speed_m_s <= 0:
        return
    length_pt = 28.0
    a = math.radians(direction_deg)
    ax.annotate(
        "",
        xy=at,
        xycoords="axes fraction",
        xytext=(-length_pt * math.cos(a), -length_pt * math.sin(a)),
        textcoords="offset points",
        arrowprops={"arrowstyle": "-|>", "color": colour, "lw": 1.8},
    )
    ax.annotate(  # centred under the arrow's head: inside the axes whichever way it points
        f"current {speed_m_s:g} m/s\ntowards {direction_deg:g} deg",
        xy=at,
        xycoords="axes fraction",
        xytext=(-length_pt * math.cos(a) / 2, -length_pt * abs(math.sin(a)) / 2 - 6),
        textcoords="offset points",
        ha="center",
        va="top",
        fontsize=8,
        color=colour,
    )


def _draw_task(ax: plt.Axes, scenario: Scenario) -> None:
    draw_waypoints(ax, scenario.waypoints_m, scenario.acceptance_radius_m)
    draw_current(ax, scenario.current_speed_m_s, scenario.current_direction_deg)


def track_frame(
    start_m: Sequence[float], waypoint_m: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors along the straight track from start to waypoint, and across it (to its left)."""
    along = np.asarray(waypoint_m, dtype=float) - np.asarray(start_m, dtype=float)
    along = along / np.linalg.norm(along)
    return along, np.array([-along[1], along[0]])


def plot_track_errors(runs: Sequence[Any], path: str | Path, title: str = "") -> Path:
    """Straight runs: the tracks, and the twin's along- and cross-track error against time.

    On a tank-sized scale every straight track looks the same; the error of the simulation
    against the recording, split along the track (ahead > 0) and across it (left > 0), shows what
    the fit gets wrong and when.

    Parameters
    ----------
    runs : sequence of ValidationRun
        Each with ``experiment`` (name, positions, scenario), ``times_s``, ``exp_positions_m``
        and ``sim_positions_m`` (:class:`eelhost.estimation.validate.ValidationRun`).
    path : str or Path
        Output PNG.
    title : str
        Figure title.

    Returns
    -------
    Path
    """
    fig = plt.figure(figsize=(12, 6.5), constrained_layout=True)
    grid = fig.add_gridspec(2, 2, width_ratios=[1.1, 1])
    ax_tracks = fig.add_subplot(grid[:, 0])
    ax_along = fig.add_subplot(grid[0, 1])
    ax_cross = fig.add_subplot(grid[1, 1], sharex=ax_along)
    colours = plt.cm.tab20(np.linspace(0, 1, max(len(runs), 1), endpoint=False))
    distance = 0.0
    for run, colour in zip(runs, colours, strict=False):
        e = run.experiment
        start, goal = e.scenario.start_position_m, e.scenario.waypoints_m[-1]
        along, across = track_frame(start, goal)
        distance = max(distance, float(np.linalg.norm(np.subtract(goal, start))))
        # the tracks in the track's own frame, the offset across it in mm: at tank scale a
        # straight run is a flat line, and the sway and drift the fit must match are millimetres
        # Each track as its mean over one tail beat (2 pi / omega): the sway is within a camera
        # pixel or two, so the raw recording steps between pixel rows; the mean over a beat
        # shows the drift across the track that the fit must match, for both alike.
        beat_s = 2.0 * math.pi / e.scenario.omega_rad_s
        for t, xy, style in ((e.t_s, e.position_m, "-"),  # every frame: the mean is finer
                             (run.times_s, run.sim_positions_m, "--")):
            rel = np.asarray(xy, dtype=float) - np.asarray(start, dtype=float)
            step = float(np.median(np.diff(t))) if len(t) > 1 else beat_s
            size = max(1, int(round(beat_s / step)))
            inner = slice(size // 2, max(size // 2 + 1, len(rel) - size // 2))  # whole beats
            ax_tracks.plot(uniform_filter1d(rel @ along, size, mode="nearest")[inner],
                           1000.0 * uniform_filter1d(rel @ across, size, mode="nearest")[inner],
                           style, color=colour, lw=1.2)
        error = np.asarray(run.sim_positions_m) - np.asarray(run.exp_positions_m)
        ax_along.plot(run.times_s, 1000.0 * (error @ along), color=colour, lw=1, label=e.name)
        ax_cross.plot(run.times_s, 1000.0 * (error @ across), color=colour, lw=1)
    if runs:
        radius = runs[0].experiment.scenario.acceptance_radius_m
        ax_tracks.plot(0.0, 0.0, "o", color="k", ms=4, label="start")
        ax_tracks.axvspan(distance - radius, distance, color="tab:green", alpha=0.12,
                          label=f"within {radius:g} m of the waypoint ({distance:g} m ahead)")
    ax_tracks.add_artist(
        ax_tracks.legend(
            [Line2D([], [], color="k"), Line2D([], [], color="k", ls="--")],
            ["experiment", "simulation"],
            loc="upper left",
            fontsize=9,
        )
    )
    legend_once(ax_tracks, loc="lower left", fontsize=9)
    ax_tracks.axhline(0.0, color="0.5", lw=0.8)
    label_axes(ax_tracks, "along the track (m)", "across the track, left > 0 (mm)")
    ax_tracks.grid(alpha=0.3)
    ax_tracks.set_title("tracks, each the mean over one tail beat (across magnified)",
                        fontsize=10)
    for ax, what in ((ax_along, "along-track error (mm)"), (ax_cross, "cross-track error (mm)")):
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_ylabel(what)
        ax.grid(alpha=0.3)
    ax_along.set_title("simulation - experiment (ahead > 0, left of the track > 0)", fontsize=10)
    ax_cross.set_xlabel("t (s)")
    ax_along.legend(fontsize=7, ncol=2, loc="best")
    if title:
        fig.suptitle(title)
    return save_figure(fig, path)


PRINT_DPI = 150  # the least a journal prints a figure at; the text sizes are set for it


def save_figure(fig: plt.Figure, path: str | Path, dpi: int = PRINT_DPI) -> Path:
    """Save a figure (PNG, or the format of the path's suffix) whole, creating its folder; close it.

    Parameters
    ----------
    fig : Figure
    path : str or Path
    dpi : int
        Resolution, at least :data:`PRINT_DPI`.

    Returns
    -------
    Path
        The file, written atomically (:func:`eelhost.files.atomic_writer`).
    """
    out = Path(path)
    try:
        with atomic_writer(out, "wb") as f:
            fig.savefig(f, dpi=max(dpi, PRINT_DPI), format=out.suffix.lstrip(".") or "png")
    finally:
        plt.close(fig)
    return out


def plot_run(
    result: RunResult,
    model: SwimmerModel,
    scenario: Scenario,
    path: str | Path,
    outline_every_s: float = 2.0,
) -> Path:
    """Write a PNG of a run, like the paper's figure 9.

    The path panel shows the robot's outline at intervals, the waypoints with their acceptance
    circles and the current's arrow; three panels show x(t), y(t) and heading(t).

    Parameters
    ----------
    result : RunResult
    model : SwimmerModel
    scenario : Scenario
    path : str or Path
        Output PNG.
    outline_every_s : float
        Interval between drawn robot outlines.

    Returns
    -------
    Path
    """
    n = model.n_links
    fig = plt.figure(figsize=(11, 6.5), constrained_layout=True)
    grid = fig.add_gridspec(3, 2, width_ratios=[1.5, 1])
    ax = fig.add_subplot(grid[:, 0])
    x, y = result.states[:, n], result.states[:, n + 1]
    ax.plot(x, y, color="k", lw=1, label="centre of mass")
    stride = (
        max(1, int(round(outline_every_s / (result.t_s[1] - result.t_s[0]))))
        if len(result.t_s) > 1
        else 1
    )
    for k in range(0, len(result.t_s), stride):
        ox, oy = robot_outline(model, result.states[k])
        first = k == 0
        ax.plot(ox, oy, "-", color="tab:orange", lw=2, alpha=0.7,
                label=f"robot every {outline_every_s:g} s" if first else None)
        ax.plot(ox[-1], oy[-1], "o", color="tab:red", ms=3, label="head" if first else None)
    if result.camera_pose.size:
        ax.plot(
            result.camera_pose[:, 0],
            result.camera_pose[:, 1],
            ".",
            ms=1,
            color="tab:gray",
            label="camera (filtered)",
        )
    _draw_task(ax, scenario)
    ax.set_aspect("equal")
    label_axes(ax)
    status = (
        "reached the goal"
        if result.failure.name == "NONE"
        else f"{result.failure.name}: {result.reason}"
    )
    ax.set_title(f"{scenario.name}: {status}", fontsize=9)
    legend_once(ax, loc="best", fontsize=8)
    heading = np.degrees(result.states[:, :n].mean(axis=1))
    for row, (vals, label) in enumerate([(x, "x (m)"), (y, "y (m)"), (heading, "heading (deg)")]):
        a = fig.add_subplot(grid[row, 1])
        a.plot(result.t_s, vals, color="k", lw=1)
        a.set_ylabel(label)
        a.grid(alpha=0.3)
        if row == 2:
            a.set_xlabel("t (s)")
    return save_figure(fig, path)


def animate_run(
    result: RunResult,
    model: SwimmerModel,
    scenario: Scenario,
    path: str | Path,
    fps: int = 15,
    speedup: float = 4.0,
) -> Path:
    """Write a GIF of the swimming robot.

    Parameters
    ----------
    result : RunResult
    model : SwimmerModel
    scenario : Scenario
    path : str or Path
        Output GIF.
    fps : int
        Frames per second of the GIF.
    speedup : float
        Simulated seconds per second of GIF.

    Returns
    -------
    Path
    """
    n = model.n_links
    dt = result.t_s[1] - result.t_s[0]
    stride = max(1, int(round(speedup / fps / dt)))
    frames = list(range(0, len(result.t_s), stride))
    fig, ax = plt.subplots(figsize=(6, 4.5))
    x, y = result.states[:, n], result.states[:, n + 1]
    pad = 0.5
    ax.set_xlim(
        min(x.min(), np.min(np.asarray(scenario.waypoints_m)[:, 0])) - pad,
        max(x.max(), np.max(np.asarray(scenario.waypoints_m)[:, 0])) + pad,
    )
    ax.set_ylim(
        min(y.min(), np.min(np.asarray(scenario.waypoints_m)[:, 1])) - pad,
        max(y.max(), np.max(np.asarray(scenario.waypoints_m)[:, 1])) + pad,
    )
    ax.set_aspect("equal")
    label_axes(ax)
    _draw_task(ax, scenario)
    (trail,) = ax.plot([], [], color="k", lw=1)
    (body,) = ax.plot([], [], "-o", color="tab:orange", lw=3, ms=3)
    label = ax.text(0.02, 0.95, "", transform=ax.transAxes, fontsize=9)

    def draw(k: int):
        trail.set_data(x[: k + 1], y[: k + 1])
        body.set_data(*robot_outline(model, result.states[k]))
        label.set_text(f"t = {result.t_s[k]:.1f} s")
        return trail, body, label

    anim = animation.FuncAnimation(fig, draw, frames=frames, blit=True)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_name(f".{out.name}.partial{out.suffix}")  # Pillow writes to a named file
    try:
        anim.save(partial, writer=animation.PillowWriter(fps=fps))
        os.chmod(partial, default_file_mode())
        os.replace(partial, out)  # whole, as every output (eelhost.files)
    finally:
        partial.unlink(missing_ok=True)
        plt.close(fig)
    return out
