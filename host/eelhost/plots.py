"""Figures of runs: the path with the robot drawn at intervals, and x(t), y(t), heading(t).

Like the paper's figure 9. Uses matplotlib's non-interactive Agg backend (no screen needed).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import animation  # noqa: E402
from matplotlib.patches import Circle, FancyArrow  # noqa: E402

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


def _draw_task(ax: plt.Axes, scenario: Scenario) -> None:
    wps = np.asarray(scenario.waypoints_m)
    for i, (wx, wy) in enumerate(wps):
        ax.add_patch(
            Circle((wx, wy), scenario.acceptance_radius_m, fill=False, ls="--", color="tab:green")
        )
        ax.plot(wx, wy, "x", color="tab:green")
        ax.annotate(f"W{i + 1}", (wx, wy), textcoords="offset points", xytext=(4, 4), fontsize=8)
    if scenario.current_speed_m_s > 0:
        vx, vy = scenario.current_m_s
        scale = 0.25 / scenario.current_speed_m_s
        ax.add_patch(FancyArrow(-0.2, -0.35, vx * scale, vy * scale, width=0.01, color="tab:blue"))
        ax.annotate(
            f"current {scenario.current_speed_m_s:.2f} m/s",
            (-0.2, -0.42),
            fontsize=8,
            color="tab:blue",
        )


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
        ax.plot(ox, oy, "-", color="tab:orange", lw=2, alpha=0.7)
        ax.plot(ox[-1], oy[-1], "o", color="tab:red", ms=3)
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
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    status = (
        "reached the goal"
        if result.failure.name == "NONE"
        else f"{result.failure.name}: {result.reason}"
    )
    ax.set_title(f"{scenario.name}: {status}", fontsize=9)
    ax.legend(loc="upper left", fontsize=8)
    heading = np.degrees(result.states[:, :n].mean(axis=1))
    for row, (vals, label) in enumerate([(x, "x (m)"), (y, "y (m)"), (heading, "heading (deg)")]):
        a = fig.add_subplot(grid[row, 1])
        a.plot(result.t_s, vals, color="k", lw=1)
        a.set_ylabel(label)
        a.grid(alpha=0.3)
        if row == 2:
            a.set_xlabel("t (s)")
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


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
    anim.save(out, writer=animation.PillowWriter(fps=fps))
    plt.close(fig)
    return out
