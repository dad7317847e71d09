import json

import numpy as np
import pytest

from eelhost.cli import main
from eelsim.record import trajectory_columns


def test_help_lists_the_subcommands(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "simulate" in out and "speeds" in out


def test_simulate_writes_trajectory_metadata_plot_and_animation(tmp_path, capsys):
    stem = tmp_path / "run"
    code = main(
        ["simulate", "straight", "--duration", "3", "--out", str(stem), "--plot", "--animate"]
    )
    assert code == 3  # the run ended flagged TOO_SLOW: eelhost.errors.exit_status_for_flag
    table = np.loadtxt(stem.with_suffix(".csv"), delimiter=",", skiprows=1)
    header = stem.with_suffix(".csv").read_text().splitlines()[0].split(",")
    assert header == trajectory_columns(6)
    assert table.shape == (301, len(header))
    assert np.allclose(np.diff(table[:, 0]), 0.01)
    assert table[-1, 1] > table[0, 1]  # swam forward (+x)
    meta = json.loads(stem.with_suffix(".json").read_text())
    assert meta["outcome"]["failure"] == "TOO_SLOW"  # 3 s is not enough to swim 1.4 m
    assert meta["scenario"]["name"] == "straight" and meta["seed"] == 0
    assert stem.with_suffix(".png").read_bytes()[:4] == b"\x89PNG"
    assert stem.with_suffix(".gif").read_bytes()[:3] == b"GIF"
    assert "did not arrive" in capsys.readouterr().out


def test_simulate_overrides_gait_waypoints_and_current(tmp_path):
    stem = tmp_path / "custom"
    code = main(
        [
            "simulate",
            "straight",
            "--gait",
            "0.61,2.7",
            "--waypoints",
            "0.5,0.1;0.9,0.1",
            "--current",
            "0.01,90",
            "--duration",
            "40",
            "--out",
            str(stem),
        ]
    )
    assert code == 0
    meta = json.loads(stem.with_suffix(".json").read_text())
    assert meta["scenario"]["amplitude_rad"] == 0.61
    assert meta["scenario"]["waypoints_m"] == [[0.5, 0.1], [0.9, 0.1]]
    assert meta["scenario"]["current_speed_m_s"] == 0.01
    assert meta["outcome"]["failure"] == "NONE"


def test_simulate_with_servo_joints_records_their_torques_and_warns_of_saturation(
        tmp_path, capsys):
    stem = tmp_path / "servo"
    code = main(["simulate", "straight", "--robot", "servo_robot.toml", "--duration", "2",
                 "--out", str(stem)])
    assert code == 3  # 2 s is too short to arrive: flagged TOO_SLOW, and the record is written
    header = stem.with_suffix(".csv").read_text().splitlines()[0].split(",")
    table = np.loadtxt(stem.with_suffix(".csv"), delimiter=",", skiprows=1)
    torque = table[:, header.index("torque_1"):header.index("torque_5") + 1]
    assert torque.shape == (201, 5) and np.all(np.isfinite(torque))
    meta = json.loads(stem.with_suffix(".json").read_text())
    assert meta["robot"]["joints"]["model"] == "servo"
    # from rest the servos ask more than their stall torque for a few steps: counted, not failed
    assert 0 < meta["outcome"]["saturated_steps"] < 50
    assert meta["outcome"]["max_torque_ratio"] > 1.0
    assert meta["outcome"]["failure"] == "TOO_SLOW"
    assert "than the servo's torque-speed line allows" in capsys.readouterr().out


def test_bad_robot_file_gives_a_one_line_error_naming_file_and_key(tmp_path, capsys):
    bad = tmp_path / "robot.toml"
    bad.write_text('name = "x"\nn_links = 1\n')
    assert main(["simulate", "straight", "--robot", str(bad), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "n_links" in err
    assert not (tmp_path / "r.csv").exists()


def test_control_period_off_the_step_grid_is_refused(tmp_path, capsys):
    assert (
        main(["simulate", "straight", "--control-period", "0.305", "--out", str(tmp_path / "r")])
        == 2
    )
    assert "not a whole multiple of the physics step" in capsys.readouterr().err
