"""The plan figure says what the terminal says: the worst clearance over every check run.

The check runs here are made up (a straight line across the tank at three heights), so the
figure is tested without a planner search: the title must name the smallest clearance of all
runs, not the first run's, and the legend must list every kind of thing drawn.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest

from eelhost.commands.plan import world_from_name
from eelhost.planning import figures
from eelhost.planning.execute import Swim
from eelhost.planning.search import Plan
from eelsim.model import SwimmerModel
from eelsim.robot import load_robot


def _swim(label: str, y_m: float, clearance_m: float, model: SwimmerModel) -> Swim:
    n = model.n_links
    t = np.linspace(0.0, 10.0, 50)
    states = np.zeros((len(t), 2 * n + 4))
    states[:, n] = np.linspace(0.3, 2.0, len(t))
    states[:, n + 1] = y_m
    return Swim(label, True, 10.0, clearance_m > 0, clearance_m, None if clearance_m > 0 else 5.0,
                0.01, None, "", t, states)


@pytest.fixture
def captured(monkeypatch):
    kept = []

    def keep(fig, path, dpi=150):
        kept.append(fig)
        return path

    monkeypatch.setattr(figures, "save_figure", keep)
    yield kept
    plt.close("all")


def test_the_plan_figure_gives_the_worst_clearance_over_every_check(captured, tmp_path):
    model = SwimmerModel.from_robot(load_robot())
    world = world_from_name("tank_5_obstacles")
    checks = [_swim("straight", 0.5, 0.058, model), _swim("turning", 0.6, 0.042, model),
              _swim("draw 1", 0.7, 0.051, model)]
    plan = Plan(True, "found", "3 legs, 22 s")
    figures.plot_plan(world, plan, checks[0], model, tmp_path / "plan.png", checks=checks)
    (fig,) = captured
    ax = fig.axes[0]
    title = ax.get_title()
    assert "worst clearance 42 mm (turning)" in title and "58 mm" not in title
    assert "over 3 runs" in title
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    for kind in ("obstacles", "start", "goal region", "other check runs (2)",
                 "its body, 12 times along the run"):
        assert any(kind in entry for entry in legend), (kind, legend)
