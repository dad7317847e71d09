import numpy as np
import pytest

from eelhost.vision.localise import Localiser, filtered_poses
from eelhost.vision.synthetic import SyntheticCamera, sample_run
from eelsim.closed_loop import simulate_closed_loop
from eelsim.dynamics import straight_state
from eelsim.model import SwimmerModel
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario


@pytest.fixture(scope="module")
def robot():
    return load_robot()


@pytest.fixture(scope="module")
def camera(robot):
    return SyntheticCamera(robot, seed=3)


@pytest.fixture(scope="module")
def localiser(robot, camera):
    return Localiser(camera.calibration(), robot)


@pytest.fixture(scope="module")
def swimming_run(robot):
    scenario = load_scenario("path1").model_copy(update={"duration_s": 8.0})
    result = simulate_closed_loop(robot, scenario)
    return sample_run(result.t_s, result.states, 30.0)


def _heading_error(a, b):
    return float(np.angle(np.exp(1j * (a - b))))


def test_localised_pose_matches_truth_on_rendered_swimming_frames(camera, localiser, swimming_run):
    picks = np.linspace(0, len(swimming_run.t_s) - 1, 24).round().astype(int)
    pos_px, heading = [], []
    for k in picks:
        frame, truth = camera.render(swimming_run.states[k], swimming_run.t_s[k])
        loc = localiser.localise(swimming_run.t_s[k], frame)
        assert loc.t_s == swimming_run.t_s[k]
        if not loc.found:
            continue  # an unread tail or head marker (about 1 frame in 80): no pose, by design
        pos_px.append(np.linalg.norm(camera.calibration().to_px(loc.com_m) - truth.com_px))
        heading.append(_heading_error(loc.heading_rad, truth.heading_rad))
        assert loc.max_joint_gap_m < 0.01  # the seen links form a rigid chain
    assert len(pos_px) >= 22
    assert np.sqrt(np.mean(np.square(pos_px))) < 0.5
    assert np.degrees(np.sqrt(np.mean(np.square(heading)))) < 1.0


def test_link_angles_are_reported_for_every_seen_link(camera, localiser, swimming_run):
    frame, truth = camera.render(swimming_run.states[60])
    loc = localiser.localise(2.0, frame)
    assert all(loc.seen)
    err = np.angle(np.exp(1j * (loc.link_angles_rad - truth.link_angles_rad)))
    assert np.degrees(np.max(np.abs(err))) < 4.0


@pytest.mark.parametrize("heading_deg", [180.0, -179.0, 90.0])
def test_heading_across_pi_is_not_averaged_to_zero(robot, camera, localiser, heading_deg):
    model = SwimmerModel.from_robot(robot)
    state = straight_state(model, np.radians(heading_deg), (0.5, 0.3))
    frame, truth = camera.render(state)
    loc = localiser.localise(0.0, frame)
    assert loc.found
    assert abs(np.degrees(_heading_error(loc.heading_rad, truth.heading_rad))) < 1.5


def test_robot_partly_out_of_view_gives_no_pose_and_names_the_missing_links(
    robot, camera, localiser
):
    model = SwimmerModel.from_robot(robot)
    # The frame's right edge is at about x = 3.23 m: the head half of the robot is outside.
    state = straight_state(model, 0.0, (3.22, 0.3))
    frame, _ = camera.render(state)
    loc = localiser.localise(1.5, frame)
    assert not loc.found
    assert loc.status == "partial"
    assert loc.com_m is None and loc.heading_rad is None
    assert loc.seen[0] and not loc.seen[-1]
    assert "6" in loc.message and "no pose" in loc.message
    assert np.isnan(loc.link_angles_rad[-1]) and np.isfinite(loc.link_angles_rad[0])


def test_robot_entirely_out_of_view_is_not_found(robot, camera, localiser):
    model = SwimmerModel.from_robot(robot)
    frame, _ = camera.render(straight_state(model, 0.0, (6.0, 0.3)))
    loc = localiser.localise(0.0, frame)
    assert loc.status == "not_found" and not loc.found and not any(loc.seen)


def test_one_hidden_interior_link_is_rebuilt_from_its_neighbours(camera, localiser, swimming_run):
    frame, truth = camera.render(swimming_run.states[100])
    sightings = [s for s in localiser.detect(frame) if s.link != 2]
    loc = localiser.from_sightings(0.0, sightings)
    assert loc.status == "rebuilt" and loc.rebuilt == (2,)
    assert loc.found
    assert np.linalg.norm(loc.com_m - truth.com_m) < 0.002
    assert abs(np.degrees(_heading_error(loc.heading_rad, truth.heading_rad))) < 1.0


@pytest.mark.parametrize("hidden", [(0,), (5,), (2, 3)])
def test_hidden_end_link_or_two_in_a_row_gives_partial(camera, localiser, swimming_run, hidden):
    frame, _ = camera.render(swimming_run.states[100])
    sightings = [s for s in localiser.detect(frame) if s.link not in hidden]
    loc = localiser.from_sightings(0.0, sightings)
    assert loc.status == "partial" and not loc.found
    for i in hidden:
        assert str(i + 1) in loc.message


def test_median_filter_holds_the_last_pose_through_frames_without_one(
    camera, localiser, swimming_run
):
    frames = [camera.render(swimming_run.states[k])[0] for k in (0, 3, 6)]
    results = [localiser.localise(k / 30, f) for k, f in zip((0, 3, 6), frames, strict=True)]
    missing = localiser.from_sightings(0.3, [])
    out = list(filtered_poses([missing, *results, missing], window=3))
    assert out[0][1] is None
    assert out[-1][1] is not None and np.allclose(out[-1][1], out[-2][1])
    xs = [r.com_m[0] for r in results]
    assert out[-2][1][0] == pytest.approx(np.median(xs))
