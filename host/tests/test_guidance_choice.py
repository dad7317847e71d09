"""The guidance law chosen per plan (``--guidance auto``; docs/planning_history.md, "A guidance law chosen
per plan"): plan with pursuit_ff and, where it finds no checked plan, with pure pursuit; the plan
carries its law, and the run loop, every replan and the take use that law.

``tank_5_obstacles`` is the world pursuit_ff finds no plan in (exhausted after 396 expansions
without the unknown current, session 19) and pure pursuit plans; 8 draws keep the check short.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_tank_replanning import OPEN, offsets_by_hand

from eelhost.cli import main
from eelhost.field.recorder import read_commands_csv
from eelhost.field.runloop import OFFSET_LIMIT_RAD, RunConfig
from eelhost.field.session import TakeNotes
from eelhost.field.take import TakeRequest, run_take
from eelhost.planning.planner import AUTO_LAWS
from eelhost.planning.tank import RunPlan, plan_for_run
from eelhost.planning.uncertainty import default_model
from eelhost.planning.world import load_world, parse_world
from eelhost.vision.synthetic import TankView
from eelsim.guidance import PURSUIT
from eelsim.robot import load_robot
from eelsim.scenario import PATH_GAIT

ROBOT = load_robot()
MODEL = default_model(ROBOT)
AUTO = {"guidance": AUTO_LAWS, "unknown_current_m_s": 0.0, "draws": 8}

# the open world of the replanning tests in a cross current
CROSS_CURRENT = {**OPEN, "current": {"speed_m_s": 0.03, "direction_deg": 90.0}}

@pytest.fixture(scope="module")
def tank5_auto() -> RunPlan:
    """``tank_5_obstacles`` planned for a run with the laws chosen per plan."""
    world = load_world("tank_5_obstacles")
    return plan_for_run(world, ROBOT, "sim://?speed=0", PATH_GAIT, MODEL, planner_options=AUTO)


def test_a_world_pursuit_ff_finds_no_plan_in_is_planned_with_pursuit_and_the_plan_says_so(
        tank5_auto):
    planned = tank5_auto
    outcome = planned.outcome
    assert outcome.found
    assert outcome.guidance == "pursuit" and planned.guidance.name == "pursuit"
    assert [t["law"] for t in outcome.laws_tried] == ["pursuit_ff"]
    assert outcome.laws_tried[0]["status"] in ("exhausted", "check_failed")
    assert "guidance pursuit, after pursuit_ff" in outcome.message
    # the time of both searches is the plan's
    assert outcome.planning_time_s >= outcome.laws_tried[0]["planning_time_s"] > 0.0
    # the replanner and every replan's planner use the plan's law, not the one tried first
    nav = planned.navigator
    assert nav.planner.options.guidance == planned.guidance == nav.planner.twin.options.guidance
    assert nav.planner_for(np.array([0.01, -0.02])).options.guidance == planned.guidance
    assert nav.events[0]["guidance"] == "pursuit"
    assert nav.events[0]["laws_tried"][0]["law"] == "pursuit_ff"


def test_a_world_pursuit_ff_plans_keeps_pursuit_ff():
    world = parse_world(CROSS_CURRENT, "open")
    planned = plan_for_run(world, ROBOT, "sim://?speed=0", PATH_GAIT, MODEL,
                           planner_options=AUTO)
    assert planned.outcome.found and planned.outcome.laws_tried == []
    law = planned.guidance
    assert law.name == "pursuit_ff" and planned.outcome.guidance == "pursuit_ff"
    # the law as the planner filled it in: the world's current, the robot's speed
    assert law.current_m_s[1] == pytest.approx(0.03, abs=1e-9) and law.speed_m_s > 0.05
    nav = planned.navigator
    assert nav.planner_for(np.array([0.0, 0.01])).options.guidance == law
    assert nav.recovery_planner_for(np.array([0.0, 0.01])).options.guidance == law
    assert nav.events[0]["guidance"] == "pursuit_ff" and "laws_tried" not in nav.events[0]


def test_the_run_steers_and_records_with_the_law_its_plan_was_found_with(tank5_auto, tmp_path):
    planned = tank5_auto
    config = RunConfig(PATH_GAIT, planned.waypoints_m, duration_s=3.0,
                       guidance=planned.guidance, start_guide=planned.start_guide)
    stem = tmp_path / "auto"
    request = TakeRequest(ROBOT, config, str(stem), TakeNotes(planned.uri), "synthetic:clean",
                          navigator=planned.navigator, camera_view=TankView.covering((3.0, 2.0)))
    run_take(request)
    frames = np.loadtxt(f"{stem}.csv", delimiter=",", skiprows=1, ndmin=2)[:, :4]
    sent = [r for r in read_commands_csv(f"{stem}.commands.csv")
            if r["event"] == "sent" and r["message"] == "SetOffset"][1:]  # after Start's 0
    assert len(sent) >= 10
    meta = json.loads(open(f"{stem}.json").read())
    plans = meta["source"]["planning"]["plans"]
    assert not any("t_switch_s" in p for p in plans)  # one plan steered the whole take
    start = planned.start_guide
    assert start is not None
    got = [r["fields"]["offset_rad"] for r in sent]
    assert np.allclose(got, offsets_by_hand(frames, sent, planned.waypoints_m, PURSUIT, start[:2],
                                            OFFSET_LIMIT_RAD), atol=1e-5)
    # pursuit_ff in the world's known current would have steered otherwise
    nav = planned.navigator
    ff = AUTO_LAWS[0].with_water(nav.world.current_m_s, nav.planner.swimming_speed_m_s)
    assert not np.allclose(got, offsets_by_hand(frames, sent, planned.waypoints_m, ff, start[:2],
                                                OFFSET_LIMIT_RAD), atol=1e-2)
    # the take records the law it steered with and the law of every plan
    assert meta["source"]["guidance"]["law"] == "pursuit"
    assert all(p["guidance"] == "pursuit" for p in plans)
    assert plans[0]["laws_tried"][0]["law"] == "pursuit_ff"


def test_plan_command_with_auto_writes_the_law_it_chose(tmp_path, capsys):
    out = tmp_path / "plan"
    assert main(["plan", "tank_5_obstacles", "--guidance", "auto", "--unknown-current", "0",
                 "--draws", "8", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "guidance: the paper's pure pursuit" in printed
    plan = json.loads((out / "plan.json").read_text())
    assert plan["found"] and plan["guidance"] == "pursuit"
    assert [t["law"] for t in plan["laws_tried"]] == ["pursuit_ff"]


def test_waypoint_runs_refuse_auto(capsys):
    status = main(["run", "--link", "sim://", "--waypoints", "1,0", "--gait", "0.4,6.28",
                   "--guidance", "auto", "--out", "/nonexistent/x"])
    assert status == 2
    assert "--guidance auto: only with --plan or --bench" in capsys.readouterr().err
