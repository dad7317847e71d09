"""Closed-loop execution with replanning: in the twin, and over sim:// (test_tank_replanning.py
has the tank's replanner in detail)."""

from __future__ import annotations

import json

import pytest

from eelhost.cli import main
from eelhost.planning.planner import Planner
from eelhost.planning.replan import execute_with_replanning
from eelhost.planning.tank import sim_uri_for_world
from eelhost.planning.uncertainty import default_model
from eelhost.planning.world import parse_world
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)
N = ROBOT.n_links

WORLD = {
    "name": "short",
    "tank": {"size_m": [3.0, 2.0]},
    "start": {"position_m": [0.6, 1.0], "heading_deg": 0.0},
    "goal": {"position_m": [1.9, 1.0], "radius_m": 0.2},
    "current": {"speed_m_s": 0.0, "direction_deg": 0.0},
    # off the straight line: the check's unknown-current draws (0.02 m/s round the circle) swim
    # a plan past a disc on the line into it
    "obstacles": [{"kind": "circle", "centre_m": [1.25, 1.4], "radius_m": 0.12}],
}


@pytest.fixture(scope="module")
def planner():
    return Planner(parse_world(WORLD, "short"), ROBOT, MODEL)


def test_robot_pushed_off_the_corridor_by_an_unknown_current_is_replanned_to_the_goal(planner):
    run = execute_with_replanning(planner, MODEL.fits["straight"], current_m_s=(0.0, -0.04))
    assert run.replans >= 1, run.message
    assert run.reached and run.collision_free, run.message
    assert run.min_clearance_m > 0
    assert len(run.outcomes) == run.replans + 1


def test_sim_uri_gets_the_worlds_start_and_current_unless_it_gives_them():
    world = parse_world({**WORLD, "current": {"speed_m_s": 0.02, "direction_deg": 90.0}}, "w")
    assert sim_uri_for_world("sim://?speed=0", world) == (
        "sim://?speed=0&start=0.6,1,0&current=0.02,90")
    assert sim_uri_for_world("sim://?current=0,0", world) == "sim://?current=0,0&start=0.6,1,0"
    assert sim_uri_for_world("serial:///dev/ttyUSB0", world) == "serial:///dev/ttyUSB0"


@pytest.mark.slow
def test_run_plan_over_sim_replans_in_an_unknown_current_and_arrives(tmp_path, capsys):
    toml = tmp_path / "short.toml"
    toml.write_text(
        'name = "short"\n[tank]\nsize_m = [3.0, 2.0]\n[start]\nposition_m = [0.6, 1.0]\n'
        "heading_deg = 0.0\n[goal]\nposition_m = [1.9, 1.0]\nradius_m = 0.2\n[current]\n"
        'speed_m_s = 0.0\ndirection_deg = 0.0\n[[obstacles]]\nkind = "circle"\n'
        "centre_m = [1.25, 1.4]\nradius_m = 0.12\n"
    )
    # a replan budget of 5 s: with the default 1 s a loaded machine's replans ran out of time
    # and the robot arrived with none; with 30 s an idle search ran 26 s (at 0.05 m/s) while
    # the robot, its clock paced by the planner's wall time, swam to the goal on its first plan
    # (the deadline's own tests are test_planning_deadline.py's); no live view: its frames
    # tripled the run's time and its own tests are test_liveview*.py's
    code = main(["run", "--link", "sim://?speed=0&current=0.04,270", "--plan", str(toml),
                 "--camera", "synthetic:clean", "--replan-budget", "5", "--no-view",
                 "--out", str(tmp_path / "run")])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "arrived: in the planned goal disc" in out
    replans = int(out.split("replans: ")[1].split()[0])
    assert replans >= 1
    # a planned run steers by default with the paper's pursuit (pursuit_ff loses the bundled
    # tank_5_obstacles: docs/planning.md, "The guidance"), and the take says which
    guidance = json.loads((tmp_path / "run.json").read_text())["source"]["guidance"]
    assert guidance["law"] == "pursuit"


def test_run_needs_waypoints_or_a_plan(tmp_path, capsys):
    assert main(["run", "--link", "sim://", "--out", str(tmp_path / "x")]) == 2
    assert "either --waypoints or --plan" in capsys.readouterr().err
