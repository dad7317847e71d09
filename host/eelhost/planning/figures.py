"""Figure of a plan, like the paper's figure 11 (matplotlib, Agg backend).

Three panels: (a) the actions of the library for a current along the robot's heading (0 deg), from
rest, with their swept hulls; (b) the hulls of one manoeuvre (swimming, straight ahead, longest)
for the eight current directions; (c) the tank: obstacles, the search tree, the planned hulls and
waypoints, and the path the twin swam with the robot drawn along it.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.patches import Circle, Polygon, Rectangle  # noqa: E402

from eelhost.planning.execute import Execution  # noqa: E402
from eelhost.planning.primitives import REST, SWIMMING, PrimitiveLibrary  # noqa: E402
from eelhost.planning.search import Plan  # noqa: E402
from eelhost.planning.world import CircleObstacle, World  # noqa: E402
from eelhost.plots import draw_current, label_axes, legend_once, robot_outline  # noqa: E402
from eelsim.model import SwimmerModel  # noqa: E402


def _actions(ax: plt.Axes, lib: PrimitiveLibrary) -> None:
    rows = lib.group(REST, lib.nearest_current_index(0.0))
    colours = plt.cm.viridis(np.linspace(0, 0.9, max(len(rows), 1)))
    for colour, i in zip(colours, rows, strict=False):
        ax.add_patch(Polygon(lib.hulls[i], closed=True, fc=colour, alpha=0.12, ec=colour, lw=0.6))
        ax.plot(*lib.paths[i].T, color=colour, lw=1.2)
        ax.plot(*lib.waypoint_rel[i], "x", color=colour, ms=5)
    ax.set_title("(a) actions from rest, current 0 deg", fontsize=9)


def _hulls_by_current(ax: plt.Axes, lib: PrimitiveLibrary) -> None:
    dirs = lib.discretisation.current_directions_deg
    colours = plt.cm.twilight(np.linspace(0, 1, len(dirs), endpoint=False))
    dist = max(lib.discretisation.distances_m)
    for ci, (d, colour) in enumerate(zip(dirs, colours, strict=True)):
        rows = [i for i in lib.group(SWIMMING, ci)
                if lib.bearing_deg[i] == 0 and lib.distance_m[i] == dist]
        for k, i in enumerate(rows):  # one legend entry per direction
            label = f"{d:g} ({lib.current_rel_deg[i]:.0f} after the lead-in)" if k == 0 else None
            ax.add_patch(Polygon(lib.hulls[i], closed=True, fill=False, ec=colour, lw=1.2,
                                 label=label))
            ax.plot(*lib.paths[i].T, color=colour, lw=0.8)
    legend_once(ax, fontsize=5, loc="upper left", title="current vs heading (deg)",
                title_fontsize=6)
    ax.set_title(f"(b) hulls, swimming, {dist:g} m ahead", fontsize=9)


def _obstacles(ax: plt.Axes, world: World) -> None:
    w, h = world.tank.size_m
    ax.add_patch(Rectangle((0, 0), w, h, fill=False, ec="black", lw=2))
    for o in world.obstacles:
        if isinstance(o, CircleObstacle):
            ax.add_patch(Circle(o.centre_m, o.radius_m, fc="0.35", ec="black"))
        else:
            ax.add_patch(Polygon(o.vertices_m, closed=True, fc="0.35", ec="black"))
    ax.add_patch(Circle(world.goal.position_m, world.goal.radius_m, fc="tab:green", alpha=0.3,
                        label="goal region"))
    ax.plot(*world.start.position_m, "o", color="tab:blue", ms=6, label="start")
    ax.add_patch(Rectangle((0, 0), 0, 0, fc="0.35", ec="black", label="obstacles"))  # legend key
    draw_current(ax, world.current.speed_m_s, world.current.direction_deg, colour="tab:cyan",
                 at=(0.12, 0.93))


def plot_plan(
    world: World,
    library: PrimitiveLibrary,
    plan: Plan,
    execution: Execution | None,
    model: SwimmerModel,
    path: str | Path,
) -> Path:
    """Draw the figure-11-style summary of a planning run and save it as a PNG.

    Parameters
    ----------
    world : World
    library : PrimitiveLibrary
    plan : Plan
    execution : Execution or None
        The twin's run of the plan (omitted from panel (c) when None).
    model : SwimmerModel
        For the robot outlines.
    path : str or Path
        Output file.

    Returns
    -------
    Path
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = plt.figure(figsize=(13, 5.2))
    grid = fig.add_gridspec(1, 3, width_ratios=[1, 1, 2.2])
    ax_a, ax_b, ax_c = (fig.add_subplot(grid[0, i]) for i in range(3))
    _actions(ax_a, library)
    _hulls_by_current(ax_b, library)
    _obstacles(ax_c, world)
    if len(plan.tree):
        segs = plan.tree.reshape(-1, 2, 2)
        ax_c.add_collection(LineCollection(list(segs), colors="0.7", lw=0.4, label="search tree"))
    for k, step in enumerate(plan.steps):
        ax_c.add_patch(Polygon(step.hull, closed=True, fc="tab:orange", alpha=0.15,
                               ec="tab:orange", lw=0.8, label="swept hulls" if k == 0 else None))
    if plan.steps:
        wps = np.asarray(plan.waypoints_m)
        ax_c.plot(wps[:, 0], wps[:, 1], "x", color="tab:red", ms=6, label="waypoints")
    if execution is not None:
        n = model.n_links
        ax_c.plot(execution.states[:, n], execution.states[:, n + 1], color="tab:blue", lw=1.5,
                  label="executed (twin)")
        for k in np.linspace(0, len(execution.t_s) - 1, 12).round().astype(int):
            ax_c.plot(*robot_outline(model, execution.states[k]), color="tab:blue", lw=1.0,
                      alpha=0.6)
    status = plan.message if execution is None else f"{plan.message}\n{execution.message}"
    ax_c.set_title(f"(c) {world.name}: {status}", fontsize=8)
    legend_once(ax_c, fontsize=7, loc="lower right")
    for ax, frame in ((ax_a, "robot frame"), (ax_b, "robot frame"), (ax_c, "tank")):
        ax.set_aspect("equal")
        ax.autoscale_view()
        label_axes(ax, f"x, {frame} (m)", f"y, {frame} (m)")
    w, h = world.tank.size_m
    ax_c.set_xlim(-0.05, w + 0.05)
    ax_c.set_ylim(-0.05, h + 0.05)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path
