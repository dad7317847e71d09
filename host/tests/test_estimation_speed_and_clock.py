"""The report's mean-speed error per gait and its check of clock offsets at their bound."""

from dataclasses import replace

import numpy as np
import pytest

from eelhost.data.virtual_tank import TABLE3, TankSettings, record_experiment
from eelhost.estimation.clock import WIDE_S, clock_check
from eelhost.estimation.coefficients_file import FittedModel
from eelhost.estimation.runs import ALIGN_S
from eelhost.estimation.speeds import mean_speed, speed_errors, speeds_markdown
from eelhost.estimation.validate import validate
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

TRUTH = TABLE3["straight"]
CLEAN = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0, pixel_m=0.0)


@pytest.fixture(scope="module")
def robot():
    return load_robot()


def declaring(exp, jitter_s):
    """The same recording, its camera declaring time stamps good to +-``jitter_s``."""
    return replace(exp, camera={**exp.camera, "timestamp_jitter_s": jitter_s})


@pytest.fixture(scope="module")
def recording(robot):
    # recorded on time, but declaring the paper's +-0.1 s time-stamp uncertainty
    task = load_scenario("straight_A0.87_w3.9").model_copy(update={"waypoints_m": [(0.5, 0.0)]})
    return declaring(record_experiment(robot, task, "straight", TRUTH, CLEAN, seed=0), ALIGN_S)


def test_mean_speed_is_the_distance_along_the_samples_over_their_span():
    t = np.linspace(0.0, 10.0, 35)
    straight = np.column_stack([0.08 * t, np.zeros_like(t)])
    assert mean_speed(t, straight) == pytest.approx(0.08)
    # a quarter circle of radius 1 m swum in 10 s: along the curve, not the chord
    a = np.linspace(0.0, np.pi / 2, 2001)
    arc = np.column_stack([np.cos(a), np.sin(a)])
    assert mean_speed(np.linspace(0, 10, 2001), arc) == pytest.approx(np.pi / 20, rel=1e-6)


def test_the_truth_predicts_its_own_speed_and_a_slower_water_predicts_a_slower_robot(
    robot, recording
):
    truth = FittedModel.of_coefficients(TRUTH, robot)
    exact = speed_errors(validate(robot, {"straight": truth}, [recording]))[0]
    assert exact.recorded_m_s > 0.02 and abs(exact.error_percent) < 0.5
    assert exact.amplitude_rad == pytest.approx(0.87) and exact.omega_rad_s == pytest.approx(3.9)
    draggy = FittedModel.of_coefficients(TRUTH.model_copy(update={"C_f": 3 * TRUTH.C_f}), robot)
    slow = speed_errors(validate(robot, {"straight": draggy}, [recording]))[0]
    assert slow.error_percent < -2.0
    table = speeds_markdown([exact, slow])
    assert f"{slow.error_percent:+.1f}" in table and "straight: mean" in table


def test_offsets_at_their_bound_are_reported_with_where_a_wider_search_puts_them(
    robot, recording
):
    truth = FittedModel.of_coefficients(TRUTH, robot)
    on_time = clock_check(validate(robot, {"straight": truth}, [recording]))
    assert on_time.at_bound == () and on_time.warning() is None
    # the same recording with its clock 0.4 s late: the best offset within +-0.1 s sits on the
    # bound, and the wider search finds the lag
    late = replace(recording, t_s=recording.t_s + 0.4)
    check = clock_check(validate(robot, {"straight": truth}, [late]))
    assert check.at_bound == (recording.name,) and check.total == 1
    assert check.wide_offsets_s[recording.name] == pytest.approx(0.4, abs=0.02)
    assert 0.4 < WIDE_S and check.most_at_bound
    assert f"+-{ALIGN_S:g} s bound" in check.warning()


def test_offsets_at_the_revisited_bound_too_are_named_as_further_still(robot, recording):
    # a clock 1.5 s late: the revisited +-1 s search ends on its own bound as well, and the
    # warning says so instead of giving 1 s as where the offset lies
    truth = FittedModel.of_coefficients(TRUTH, robot)
    late = replace(recording, t_s=recording.t_s + 1.5)
    check = clock_check(validate(robot, {"straight": truth}, [late]))
    assert check.at_bound == (recording.name,)
    assert check.wide_offsets_s[recording.name] == pytest.approx(WIDE_S)
    assert check.wide_s == WIDE_S  # ten times the declared 0.1 s is no wider
    assert check.beyond_wide == (recording.name,)
    assert f"1 of them at +-{WIDE_S:g} s again (further still)" in check.warning()
    # within the revisited bound nothing is further
    inside = clock_check(validate(robot, {"straight": truth},
                                  [replace(recording, t_s=recording.t_s + 0.4)]))
    assert inside.beyond_wide == () and "further still" not in inside.warning()


@pytest.mark.parametrize(("declared_s", "found_s", "at_bound"),
                         [(0.0, 0.0, False), (0.1, 0.1, True), (0.5, 0.4, False)])
def test_the_clock_search_is_as_wide_as_the_time_stamp_uncertainty_the_recording_declares(
    robot, recording, declared_s, found_s, at_bound
):
    # a bound is a statement about the recording's clock (docs/estimation.md, "Validation"): a
    # hardware-triggered camera (0 declared) is compared on its own clock only, a looser one is
    # searched as far as it declares. The same recording 0.4 s late under each declaration:
    late = declaring(replace(recording, t_s=recording.t_s + 0.4), declared_s)
    truth = FittedModel.of_coefficients(TRUTH, robot)
    runs = validate(robot, {"straight": truth}, [late])
    row = runs[0].row
    assert row.clock_bound_s == declared_s
    assert row.clock_offset_s == pytest.approx(found_s, abs=0.015)
    check = clock_check(runs)
    assert (check.at_bound == (late.name,)) is at_bound
    assert check.total == (0 if declared_s == 0 else 1)
    assert (check.warning() is not None) is at_bound
    if declared_s == 0:  # nothing searched: the aligned E_x is the recorded clock's
        assert row.Ex_mean_BL == row.Ex_mean_unaligned_BL
    # a bound given explicitly overrides what the recordings declare
    forced = validate(robot, {"straight": truth}, [late], align_s=0.2)[0].row
    assert forced.clock_bound_s == 0.2 and forced.clock_offset_s == pytest.approx(0.2)


def test_a_wider_declared_bound_is_revisited_ten_times_wider(robot, recording):
    truth = FittedModel.of_coefficients(TRUTH, robot)
    late = declaring(replace(recording, t_s=recording.t_s + 1.5), 0.3)
    check = clock_check(validate(robot, {"straight": truth}, [late]))
    assert check.at_bound == (late.name,) and check.wide_s == pytest.approx(3.0)
    assert check.wide_offsets_s[late.name] == pytest.approx(1.5, abs=0.02)
    assert check.beyond_wide == () and "+-0.3 s bound" in check.warning()
