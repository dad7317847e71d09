"""``eelbot run --plan``: its live view predicts with the planner's model and follows replans, and
``--check-unknown-current`` reaches the planner outside ``--bench`` too (docs/planning.md, "The
live view of a planned run")."""

from __future__ import annotations

import json

import pytest
from test_planning_model_built_once import FITTED, OPEN_WORLD

import eelhost.commands.run as run_command
from eelhost.cli import main
from eelhost.planning import tank


class RecordingView:
    """A live display that keeps what it was built with and every frame's steered waypoints."""

    made: list[RecordingView] = []

    def __init__(self, calibration, robot, config, **options) -> None:  # noqa: ANN001
        self.robot, self.config, self.options = robot, config, options
        self.waypoints: list = []
        self.on_stop = None
        RecordingView.made.append(self)

    @property
    def url(self) -> str:
        return "recording://"

    def update(self, report) -> None:  # noqa: ANN001
        self.waypoints.append(report.waypoints_m)

    def close(self) -> None:
        pass


def test_a_planned_runs_view_swims_the_fitted_robot_in_the_worlds_and_fitted_current(
        tmp_path, monkeypatch, capsys):
    world = tmp_path / "open.toml"
    world.write_text(OPEN_WORLD.replace("speed_m_s = 0.0", "speed_m_s = 0.01"))
    (tmp_path / "coefficients.json").write_text(json.dumps(FITTED))
    RecordingView.made = []
    monkeypatch.setattr(run_command, "LiveView", RecordingView)
    code = main(["run", "--link", "sim://?speed=0", "--plan", str(world), "--coefficients-file",
                 str(tmp_path / "coefficients.json"), "--duration", "1",
                 "--camera", "synthetic:clean", "--view-port", "0",
                 "--out", str(tmp_path / "take")])
    assert code == 0, capsys.readouterr().out
    (view,) = RecordingView.made
    # the fitted model's robot (C_d 0.7, not the robot file's), in the world's 0.01 m/s towards
    # 0 deg plus the fit's ambient 0.01 m/s towards 0 deg
    assert view.options["twin"].hydrodynamics.as_array()[1] == pytest.approx(0.7)
    assert view.options["current_m_s"] == pytest.approx((0.02, 0.0), abs=1e-12)
    # every frame tells the view the waypoints steered to (here the first plan's)
    first = [(float(x), float(y)) for x, y in view.config.waypoints_m]
    assert view.waypoints and all(w == first for w in view.waypoints)


def test_run_plan_hands_check_unknown_current_and_restarts_to_the_planner(tmp_path, monkeypatch):
    seen: dict = {}

    def planned(*args, **kwargs):  # noqa: ANN002, ANN003
        seen.update(kwargs["planner_options"], restarts=kwargs["restarts"])
        raise ValueError("stop here: the options are what this test reads")

    monkeypatch.setattr(tank, "plan_for_run", planned)
    with pytest.raises(ValueError, match="stop here"):
        main(["run", "--link", "sim://?speed=0", "--plan", "tank_5_obstacles",
              "--check-unknown-current", "0.01", "--no-view", "--out", str(tmp_path / "x")])
    assert seen["unknown_current_m_s"] == 0.01
    assert seen["restarts"] == 2  # the restart from rest is on by default


def test_a_negative_restart_count_is_refused_naming_the_option(tmp_path, capsys):
    code = main(["run", "--link", "sim://?speed=0", "--plan", "tank_5_obstacles",
                 "--restarts", "-1", "--no-view", "--out", str(tmp_path / "x")])
    assert code == 2
    assert "--restarts" in capsys.readouterr().err
