"""Figure of a plan, like the paper's figure 11 (c) (matplotlib, Agg backend).

The tank: obstacles, the search tree, the planned waypoints and the centre-of-mass path of every
planned leg as the search swam it, the path of the twin's first check run with the robot's body
drawn along it, and the paths of the other check runs. The title gives the worst clearance over
all the check runs, the figure ``eelbot plan`` prints.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
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
from eelhost.plots import (  # noqa: E402
    draw_current,
    label_axes,
    legend_once,
    robot_outline,
    save_figure,
)
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
    checks: Sequence[Swim] = (),
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
    checks : sequence of Swim
        Every check run of the plan (the fits and the draws of the water); their paths are
        drawn thin, and the title gives the worst clearance over them all.

    Returns
    -------
    Path
    """
    fig, ax = plt.subplots(figsize=(9, 7.4))
    _obstacles(ax, world)
    if len(plan.tree):
        segs = plan.tree.reshape(-1, 2, 2)
        ax.add_collection(LineCollection(list(segs), colors="0.7", lw=0.4, label="search tree"))
    for k, leg in enumerate(plan.legs):
        ax.plot(*leg.com_m.T, color="tab:orange", lw=2.5, alpha=0.6,
                label="planned legs (as swum by the search)" if k == 0 else None)
    if plan.legs:
        wps = np.asarray(plan.waypoints_m)
        ax.plot(wps[:, 0], wps[:, 1], "x", color="tab:red", ms=7, mew=2, label="waypoints")
    n = model.n_links
    others = [c for c in checks if c is not swim]
    for k, other in enumerate(others):
        ax.plot(other.states[:, n], other.states[:, n + 1], color="tab:purple", lw=0.6,
                alpha=0.5, label=f"other check runs ({len(others)})" if k == 0 else None)
    if swim is not None:
        ax.plot(swim.states[:, n], swim.states[:, n + 1], color="tab:blue", lw=1.4,
                label=f"twin check ({swim.label}), centre of mass")
        for j, k in enumerate(np.linspace(0, len(swim.t_s) - 1, 12).round().astype(int)):
            ax.plot(*robot_outline(model, swim.states[k]), color="tab:blue", lw=1.0, alpha=0.6,
                    label="its body, 12 times along the run" if j == 0 else None)
    title = [f"{world.name}: {plan.message}", _check_line(swim, checks)]
    ax.set_title("\n".join(textwrap.fill(line, 110) for line in title), fontsize=9)
    # below the tank, not over its obstacles
    legend_once(ax, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=3)
    ax.set_aspect("equal")
    label_axes(ax, "x, tank (m)", "y, tank (m)")
    w, h = world.tank.size_m
    ax.set_xlim(-0.05, w + 0.05)
    ax.set_ylim(-0.05, h + 0.05)
    fig.tight_layout()
    return save_figure(fig, path)


def _check_line(swim: Swim | None, checks: Sequence[Swim]) -> str:
    """The check in one line: the worst clearance over every run, as the terminal says it."""
    runs = list(checks) or ([swim] if swim is not None else [])
    if not runs:
        return "not checked in the twin"
    worst = min(runs, key=lambda c: c.min_clearance_m)
    failed = sum(not c.ok for c in runs)
    return (f"twin check over {len(runs)} run{'s' if len(runs) != 1 else ''}: worst clearance "
            f"{worst.min_clearance_m * 1000:.0f} mm ({worst.label}); "
            + (f"{failed} failed" if failed else "every run reached the goal without contact"))
