"""The planner's twin: restarted runs, frames, and the body's clearance.

The search swims every leg from the state the previous leg left; these tests check that doing so
is the same physics as one uninterrupted run, and that a leg rotated to another heading in a
correspondingly rotated current is the same leg (docs/planning.md, "The twin").
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from eelhost.planning.body import body_points, link_endpoints
from eelhost.planning.twin import Twin
from eelhost.planning.uncertainty import default_model
from eelsim.closed_loop import LoopOptions
from eelsim.robot import load_robot
from eelsim.scenario import PATH_GAIT

ROBOT = load_robot()
N = ROBOT.n_links
MODEL = default_model(ROBOT)


def rotate(xy, angle):
    c, s = math.cos(angle), math.sin(angle)
    xy = np.asarray(xy, dtype=float)
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], -1)


def rotate_state(state, angle):
    out = state.copy()
    out[:N] += angle
    out[N : N + 2] = rotate(state[N : N + 2], angle)
    out[2 * N + 2 :] = rotate(state[2 * N + 2 :], angle)
    return out


@pytest.fixture(scope="module")
def swimming():
    """A twin in a current, and the state of a robot swimming at a restart step."""
    twin = Twin(ROBOT, MODEL.sets, PATH_GAIT, LoopOptions(), (0.03, 0.0))
    lead = twin.run([[(0.6, 0.0), (2.0, 0.0)]], 30.0, stride=1)
    step = twin.restart_steps * 20
    return twin, lead, step


@pytest.mark.parametrize("heading_deg", [90.0, 200.0, 315.0])
def test_leg_rotated_to_any_heading_in_a_rotated_current_matches_a_fresh_simulation(
    swimming, heading_deg
):
    twin, lead, step = swimming
    state = lead.states[0, step]
    waypoint = (1.0, 0.3)
    base = twin.run([[waypoint]], 20.0, states=state[None], start_steps=[step],
                    coefficient_index=[1], stride=1)
    a = math.radians(heading_deg)
    there = Twin(ROBOT, MODEL.sets, PATH_GAIT, LoopOptions(), tuple(rotate((0.03, 0.0), a)))
    fresh = there.run([[tuple(rotate(waypoint, a))]], 20.0,
                      states=rotate_state(state, a)[None], start_steps=[step],
                      coefficient_index=[1], stride=1)
    assert fresh.final_step[0] == base.final_step[0]
    end = int(base.final_step[0])
    expected = rotate(base.states[0, : end + 1, N : N + 2], a)
    got = fresh.states[0, : end + 1, N : N + 2]
    # the camera's pixels are the only thing not rotated with the world
    assert np.abs(got - expected).max() < 2e-3


def test_run_restarted_from_its_own_state_reproduces_the_uninterrupted_run(swimming):
    twin, lead, step = swimming
    rest = twin.run([[(0.6, 0.0), (2.0, 0.0)]], 30.0 - step * twin.dt_s,
                    states=lead.states[0, step][None], start_steps=[step], stride=1)
    # at ``step`` the robot is still steering to the first waypoint, as the restart does
    assert np.hypot(*(lead.states[0, step, N : N + 2] - (0.6, 0.0))) > 0.15
    end = min(int(rest.final_step[0]), int(lead.final_step[0]) - step)
    gap = np.hypot(*(rest.states[0, : end + 1, N : N + 2]
                     - lead.states[0, step : step + end + 1, N : N + 2]).T)
    # the restart's first offset comes from a median filter holding one frame, not five
    assert gap.max() < 0.01


def test_body_points_lie_on_the_link_centre_lines(swimming):
    twin, lead, step = swimming
    states = lead.states[0, [0, step, 2 * step]]
    ends = link_endpoints(twin_model(), states)
    pts = body_points(twin_model(), states, 4)
    np.testing.assert_allclose(pts[:, ::4], ends)
    np.testing.assert_allclose(pts[:, 2::4], 0.5 * (ends[:, :-1] + ends[:, 1:]))
    # the links join: consecutive link end points are the body's total length apart in sum
    lengths = np.hypot(*np.diff(ends, axis=1).transpose(2, 0, 1)).sum(axis=1)
    np.testing.assert_allclose(lengths, 2 * twin_model().half_length_m.sum())


def twin_model():
    from eelsim.model import SwimmerModel

    return SwimmerModel.from_robot(ROBOT, MODEL.sets[0])


def test_an_ilos_run_restarted_with_its_guidance_state_continues_as_the_uninterrupted_one():
    # ILOS's integral and leg are the host controller's state: a restart that carries them
    # (Runs.guidance_state) continues the run; one that drops the integral does not
    from eelhost.planning.planner import PLANNING_GUIDANCE

    twin = Twin(ROBOT, MODEL.sets, PATH_GAIT, LoopOptions(guidance=PLANNING_GUIDANCE),
                (0.0, 0.025))
    waypoints = [(1.0, 0.0), (1.6, -0.3)]
    lead = twin.run([waypoints], 40.0, stride=1, guidance=[(0.0, 0.0, 0.0, 0.0)])
    # a restart step on the first leg, well short of its waypoint's circle
    com_at = lead.states[0, :, N : N + 2]
    step = next(k for k in range(0, len(com_at), twin.restart_steps) if com_at[k, 0] > 0.5)
    assert np.hypot(*(com_at[step] - (1.0, 0.0))) > 0.3
    assert np.abs(lead.integral_s[0, step]).max() > 0.05  # the integral has learnt the current
    carried = lead.guidance_state(0, step, (0.0, 0.0))
    dropped = (0.0, 0.0, 0.0, 0.0)
    rest = twin.run([waypoints] * 2, 40.0 - step * twin.dt_s,
                    states=np.repeat(lead.states[0, step][None], 2, axis=0),
                    start_steps=[step, step], stride=1, guidance=[carried, dropped])
    gaps = []
    for r in range(2):
        end = min(int(rest.final_step[r]), int(lead.final_step[0]) - step)
        gaps.append(np.hypot(*(rest.states[r, : end + 1, N : N + 2]
                               - lead.states[0, step : step + end + 1, N : N + 2]).T).max())
    # the restart's first offset comes from a median filter holding one frame, not five
    assert gaps[0] < 0.01, gaps
    assert gaps[1] > 2 * gaps[0], gaps
