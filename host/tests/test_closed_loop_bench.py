"""The closed-loop benchmark's own contact geometry (written apart from the planner's)."""

from __future__ import annotations

import json
from dataclasses import asdict

import numpy as np
import pytest

from eelhost.benchmarks.closed_loop import (
    WorldResult,
    calm_and_early,
    estimate_error_mm,
    glide_on,
    run_closed_loop_bench,
    summary_lines,
    true_clearance_m,
    water_for,
)
from eelhost.planning.body import link_endpoints
from eelhost.planning.uncertainty import default_model
from eelhost.planning.world import parse_world
from eelhost.xil.virtual_robot import DT_US, VirtualRobot
from eelsim.dynamics import straight_state
from eelsim.model import SwimmerModel
from eelsim.robot import load_robot

ROBOT = load_robot()
BODY = SwimmerModel.from_robot(ROBOT)
WORLD = parse_world({
    "name": "w", "tank": {"size_m": [3.0, 2.0]},
    "start": {"position_m": [0.6, 1.0], "heading_deg": 0.0},
    "goal": {"position_m": [2.4, 1.0], "radius_m": 0.2},
    "current": {"speed_m_s": 0.0, "direction_deg": 0.0},
    "obstacles": [{"kind": "circle", "centre_m": [1.5, 1.0], "radius_m": 0.15},
                  {"kind": "polygon", "vertices_m": [[2.0, 0.2], [2.4, 0.2], [2.4, 0.5],
                                                     [2.0, 0.5]]}],
}, "w")


def test_a_straight_body_beside_a_wall_is_its_distance_less_its_half_width():
    for gap in (0.05, 0.01, -0.005):
        y = float(BODY.half_axis_horizontal_m.max()) + gap
        state = straight_state(BODY, 0.0, (0.8, y))
        assert true_clearance_m(WORLD, BODY, state[None])[0] == pytest.approx(gap, abs=1e-9)


def test_the_true_body_is_never_closer_than_the_planners_conservative_one():
    # the planner's body: link centre lines widened by the largest half width all round; the
    # benchmark's: each link its own stadium inside that, so never nearer to anything
    rng = np.random.default_rng(3)
    states = []
    for _ in range(300):
        s = straight_state(BODY, rng.uniform(-np.pi, np.pi), (rng.uniform(0.3, 2.7),
                                                              rng.uniform(0.3, 1.7)))
        s[: BODY.n_links] += np.cumsum(rng.normal(0, 0.25, BODY.n_links))
        states.append(s)
    states = np.asarray(states)
    ours = true_clearance_m(WORLD, BODY, states)
    b_max = float(BODY.half_axis_horizontal_m.max())
    planner = WORLD.body_clearance(link_endpoints(BODY, states)) - b_max  # exact at every state
    # (the planner's gap stops at minus its half width, where the centre line touches)
    measured = planner > -b_max + 1e-9
    assert np.all(ours[measured] >= planner[measured] - 1e-6)
    assert (ours < 0).sum() > 10 and np.all(planner[ours < 0] < 0)  # contacts seen by both
    # each stadium lies within 2 b_max of the planner's capsule around the same link (its caps
    # end at the tip, b_max short of the capsule's; its width at most b_max less)
    assert np.all((ours - planner)[measured & (ours > 0)] <= 2 * b_max + 1e-6)


def test_the_virtual_robots_water_is_seeded_and_within_its_bounds():
    model = default_model(ROBOT)
    a, b = water_for(7, model), water_for(7, model)
    assert a == b and water_for(8, model) != a
    speeds = [np.hypot(*water_for(s, model)["unknown_current_m_s"]) for s in range(50)]
    assert max(speeds) <= 0.02 and min(speeds) >= 0.0


def test_results_written_with_a_field_since_removed_still_read_back(tmp_path):
    # session 6's lines carry ``escapes`` (the escape leg, removed since): a resumed benchmark
    # reads them and runs no world again
    line = asdict(WorldResult(5000, False, "exhausted", detail="no plan"))
    (tmp_path / "results.jsonl").write_text(json.dumps({**line, "escapes": 0}) + "\n")
    got = run_closed_loop_bench(ROBOT, default_model(ROBOT), range(5000, 5001), tmp_path)
    assert got == [WorldResult(5000, False, "exhausted", detail="no plan")]


def test_the_summary_counts_shift_repairs_and_reads_results_written_before_them():
    old = WorldResult(5000, True, "found", "arrived", reached=True, min_clearance_m=0.05)
    repaired = WorldResult(5001, True, "found", "arrived", reached=True, min_clearance_m=0.04,
                           replans=3, shift_repairs=2)
    stopped = WorldResult(5002, True, "found", "no_safe_continuation", min_clearance_m=0.03,
                          replans=1, shift_repairs=1)
    lines = summary_lines([old, repaired, stopped])
    assert "- shift repairs switched in: 3, in 2 runs (1 of them reached the goal)" in lines
    assert not any("shift repair" in line for line in summary_lines([old]))


def test_the_summary_counts_calm_replans_and_their_cuts_only_where_the_budget_was_on():
    old = WorldResult(5000, True, "found", "arrived", reached=True, min_clearance_m=0.05)
    calm = WorldResult(5001, True, "found", "arrived", reached=True, min_clearance_m=0.04,
                       calm_budget_s=3.0, calm_replans=4, calm_found=1, calm_cut=2)
    lines = summary_lines([old, calm])
    assert ("- calm replans (in a moved current estimate, budget 3 s): 4, of which 1 found a "
            "plan and 2 were cut short for an urgent replan") in lines
    assert not any("calm replans" in line for line in summary_lines([old]))


def test_early_replans_are_counted_apart_from_the_calm_ones_though_both_have_a_longer_budget():
    events = [{"reason": "current_estimate", "budget_s": 3.0, "status": "found"},
              {"reason": "current_estimate", "budget_s": 1.0, "status": "exhausted"},
              {"reason": "early_margin", "budget_s": 2.0, "status": "exhausted"},
              {"reason": "early_margin", "budget_s": 2.0, "status": "found", "cut_for": "x"},
              {"reason": "left_corridor", "budget_s": 1.0, "status": "found"}]
    calm, early = calm_and_early(events, 1.0)
    assert calm == events[:1] and early == events[2:4]
    assert calm_and_early(events, None)[0] == []
    world = WorldResult(5002, True, "found", "arrived", reached=True, min_clearance_m=0.04,
                        calm_budget_s=3.0, calm_replans=1, calm_found=1, early_replans=2,
                        early_found=1, early_cut=1)
    lines = summary_lines([world])
    assert ("- early replans (the look-ahead's capsule under the early margin): 2, of which 1 "
            "found a plan and 1 were cut short for an urgent replan") in lines
    assert any(line.startswith("- calm replans (in a moved current estimate, budget 3 s): 1,")
               for line in lines)


def test_the_estimate_error_compares_each_frame_with_the_plants_step_at_its_time():
    # the plant's trace holds a state every physics step from the gait's start (the frames'
    # clock); a frame's estimate 5 mm off its own step's body is 5 mm off, not off by the motion
    # between steps
    dt = DT_US * 1e-6
    steps = np.arange(400)
    trace = np.array([straight_state(BODY, 0.0, (0.5 + 0.1 * k * dt, 1.0)) for k in steps])
    trace[:, : BODY.n_links] += 0.3 * np.sin(steps * dt * 4.0)[:, None] * np.linspace(-1, 1, BODY.n_links)
    shift = np.zeros(BODY.n_links + 2)
    shift[BODY.n_links] = 0.005  # the centre of mass 5 mm off along x
    history = [(k * dt, trace[k, : BODY.n_links + 2] + shift) for k in range(0, 400, 33)]
    got = estimate_error_mm(BODY, history, trace)
    assert got["frames"] == len(history)
    assert got["p50_mm"] == got["max_mm"] == pytest.approx(5.0)
    assert estimate_error_mm(BODY, [], trace) == {"frames": 0}
    line = next(s for s in summary_lines([WorldResult(5000, True, "found", "arrived",
                                                      reached=True, estimate_error_mm=got)])
                if "body estimate" in s)
    assert "largest in any frame 5 mm" in line


def test_a_stopped_body_carried_by_the_water_is_caught_in_the_coast_after_the_take():
    # a robot that never swims (no Start), 0.1 m/s of current towards the disc: the take's
    # trace ends clear, the coast after it reaches the disc, and the gap shrinks all along
    robot = VirtualRobot(ROBOT, start_position_m=(1.0, 1.0), current_m_s=(0.1, 0.0))
    robot.trace = []
    robot.advance_to(200_000)
    before = true_clearance_m(WORLD, robot.model, np.asarray(robot.trace))
    done = len(robot.trace)
    glide_on(robot, longest_s=3.0, rest_m_s=0.0)
    coast = true_clearance_m(WORLD, robot.model, np.asarray(robot.trace[done - 1 :]))
    assert before.min() > 0.0 and coast[0] == pytest.approx(before[-1])
    assert len(coast) == round(3.0e6 / DT_US) + 1
    assert coast.min() < 0.0 and np.all(np.diff(coast[: int(np.argmin(coast))]) <= 1e-9)


def test_the_coast_lasts_while_the_stopped_body_glides_through_the_water():
    # a straight body let go at 0.08 m/s in still water glides for many seconds (axial drag is
    # small); the glide ends within a second of its speed falling under the rest speed
    robot = VirtualRobot(ROBOT, start_position_m=(0.6, 1.0))
    n = BODY.n_links
    robot.trace = []
    robot.advance_to(0)
    robot._x = robot._x.copy()
    robot._x[2 * n + 2] = 0.08
    robot._x_next = robot._x.copy()
    done = len(robot.trace)
    glide_on(robot, longest_s=30.0, rest_m_s=0.06)
    coast = np.asarray(robot.trace[done - 1 :])
    speeds = np.hypot(*np.asarray(robot.trace)[:, 2 * n + 2 : 2 * n + 4].T)
    seconds = (len(coast) - 1) * DT_US * 1e-6
    assert 1.0 < seconds < 29.0 and speeds[-1] < 0.06
    assert speeds[-1 - round(1.0e6 / DT_US)] >= 0.06  # a second earlier it still glided faster


def test_the_summary_names_a_contact_while_the_robot_stops():
    runs = [WorldResult(1, True, "found", "arrived", reached=True, min_clearance_m=0.05,
                        coast_clearance_m=-0.004, coast_contact=True),
            WorldResult(2, True, "found", "arrived", reached=True, min_clearance_m=0.05,
                        coast_clearance_m=0.03)]
    text = "\n".join(summary_lines(runs))
    assert "1 of 2 runs (seeds 1); smallest clearance -4 mm; the glide after the Stop lasted" \
        in text
    assert "seed 1: arrived (true body 50 mm clear; touched while stopping, 4 mm deep)" in text
    old = WorldResult(3, True, "found", "arrived", reached=True, min_clearance_m=0.05)
    assert "coast" not in "\n".join(summary_lines([old]))  # results written before it


def test_the_summary_splits_the_plan_share_and_the_goal_by_the_world_s_own_current():
    from eelhost.planning.worlds import generate_world

    seeds = list(range(600, 640))  # only their worlds are generated here
    speeds = {s: generate_world(s).current.speed_m_s for s in seeds}
    slow = [s for s in seeds if speeds[s] < 0.02][:2]
    fast = [s for s in seeds if speeds[s] >= 0.04][:1]
    assert len(slow) == 2 and len(fast) == 1
    results = [WorldResult(slow[0], True, "found", "arrived", reached=True, min_clearance_m=0.05),
               WorldResult(slow[1], False, "exhausted"),
               WorldResult(fast[0], True, "found", "no_safe_continuation", min_clearance_m=0.04)]
    line = next(x for x in summary_lines(results) if x.startswith("- by the world's own"))
    assert line == ("- by the world's own current: 0-0.02 m/s: planned 1 of 2, goal 1 of 1; "
                    "0.02-0.04 m/s: planned 0 of 0, goal 0 of 0; "
                    "from 0.04 m/s: planned 1 of 1, goal 0 of 1")


def test_the_summary_counts_corridor_replans_answered_within_a_second_and_names_the_late_ones():
    # issue 28's target: a replan ready within 1 s of the robot leaving the corridor
    old = WorldResult(1, True, "found", "arrived", reached=True)
    quick = WorldResult(2, True, "found", "arrived", reached=True,
                        corridor_ready_s=[0.4, 1.0], corridor_cpu_s=[0.2, 0.3])
    late = WorldResult(3, True, "found", "arrived", reached=True,
                       corridor_ready_s=[1.54], corridor_cpu_s=[None])
    line = next(x for x in summary_lines([old, quick, late]) if "leaving the corridor" in x)
    assert "2 of 3" in line and "1.54 s" in line and "?" in line
    assert not any("leaving the corridor" in x for x in summary_lines([old]))
    quiet = next(x for x in summary_lines([quick]) if "leaving the corridor" in x)
    assert "2 of 2" in quiet and "late" not in quiet


def test_the_summary_counts_least_bad_swims_and_what_the_runs_judged_for_them_did():
    runs = [WorldResult(1, True, "found", "no_safe_continuation", min_clearance_m=0.03,
                        coast_clearance_m=0.02, least_bad=2),
            WorldResult(2, True, "found", "no_safe_continuation", min_clearance_m=0.03,
                        coast_clearance_m=-0.005, coast_contact=True, least_bad_none=1),
            WorldResult(3, True, "found", "arrived", reached=True, min_clearance_m=0.05)]
    text = "\n".join(summary_lines(runs))
    assert ("least-bad swims instead of a stop the twin drifted within the margin: 2 in 1 runs, "
            "none beating the stop 1 times; of the 2 runs judged, 0 reached the goal, 0 touched "
            "while swimming, 1 while stopping") in text
    assert "least-bad" not in "\n".join(summary_lines(runs[2:]))  # none judged, no line
