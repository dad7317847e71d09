"""Figure of a plan, like the paper's figure 11 (c) (matplotlib, Agg backend).

The tank: obstacles, the search tree, the planned waypoints and the centre-of-mass path of every
planned leg as the search swam it, and the path of the twin's check run with the robot drawn
along it.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.patches import Circle, Polygon, Rectangle  # noqa: E402

from eelhost.planning.execute import Swim  # noqa: E402
from eelhost.planning.search import Plan  # noqa: E402
from eelhost.planning.world import CircleObstacle, World  # noqa: E402
from eelhost.plots import draw_current, label_axes, legend_once, robot_outline  # noqa: E402
from eelsim.model import SwimmerModel  # noqa: E402


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
    plan: Plan,
    swim: Swim | None,
    model: SwimmerModel,
    path: str | Path,
) -> Path:
    """Draw the tank with the plan and the twin's run of it, and save it as a PNG.

    Parameters
    ----------
    world : World
    plan : Plan
    swim : Swim or None
        The twin's run of the plan (omitted when None).
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
    fig, ax = plt.subplots(figsize=(9, 6.4))
    _obstacles(ax, world)
    if len(plan.tree):
        segs = plan.tree.reshape(-1, 2, 2)
        ax.add_collection(LineCollection(list(segs), colors="0.7", lw=0.4, label="search tree"))
    for k, leg in enumerate(plan.legs):
        ax.plot(*leg.com_m.T, color="tab:orange", lw=2.5, alpha=0.6,
                label="planned legs (as swum by the search)" if k == 0 else None)
    if plan.legs:
        wps = np.asarray(plan.waypoints_m)
        ax.plot(wps[:, 0], wps[:, 1], "x", color="tab:red", ms=6, label="waypoints")
    if swim is not None:
        n = model.n_links
        ax.plot(swim.states[:, n], swim.states[:, n + 1], color="tab:blue", lw=1.2,
                label=f"twin check ({swim.label})")
        for k in np.linspace(0, len(swim.t_s) - 1, 12).round().astype(int):
            ax.plot(*robot_outline(model, swim.states[k]), color="tab:blue", lw=1.0, alpha=0.6)
    status = plan.message if swim is None else f"{plan.message}\n{swim.message}"
    ax.set_title(f"{world.name}: {status}", fontsize=8)
    legend_once(ax, fontsize=7, loc="lower right")
    ax.set_aspect("equal")
    label_axes(ax, "x, tank (m)", "y, tank (m)")
    w, h = world.tank.size_m
    ax.set_xlim(-0.05, w + 0.05)
    ax.set_ylim(-0.05, h + 0.05)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path
