"""Coefficients and datasets that must belong to their robot (issue 31, item 4).

A coefficients.json records the robot it was fitted on (name, N, geometry fingerprint) and is
refused on another unless the user says so; a dataset's robot is looked for in its own folder
only, never in the working folder.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from eelhost.cli import main
from eelhost.data.experiments import DataError, load_dataset
from eelhost.estimation.coefficients_file import (
    CoefficientsError,
    read_coefficients,
    robot_record,
    write_coefficients,
)
from eelhost.estimation.optimise import FitResult
from eelhost.estimation.space import ParameterSpace
from eelhost.planning.uncertainty import CoefficientsFileError, read_coefficient_model
from eelsim.robot import load_robot, parse_robot
from eelsim.tomlfile import parse_toml

REPO = Path(__file__).resolve().parents[2]
BUNDLED = REPO / "datasets" / "paper_virtual_tank"
PAPER = load_robot()
PAPER_TEXT = (REPO / "sim" / "eelsim" / "data" / "paper_robot.toml").read_text()
FOUR_TEXT = PAPER_TEXT.replace("n_links = 6", "n_links = 4").replace(
    'name = "Raj & Thakur anguilliform robot (paper default)"', 'name = "four-link test robot"')
FOUR = parse_robot(parse_toml(FOUR_TEXT, "<four>", ValueError), "<four>")


def _fit_file(path: Path, robot) -> Path:
    space = ParameterSpace.for_robot(robot, current=False)
    fit = FitResult("cmaes", space, np.array([0.008, 0.776, 0.618, 0.007]), 0.1)
    return write_coefficients(path, {"straight": fit, "turning": fit}, robot=robot)


def _dataset(tmp_path: Path, robot_text: str | None) -> Path:
    folder = tmp_path / "ds"
    shutil.copytree(BUNDLED, folder)
    if robot_text is None:
        (folder / "robot.toml").unlink()
    else:
        (folder / "robot.toml").write_text(robot_text)
    return folder


def test_the_robot_record_tells_robots_apart_by_geometry_not_by_name():
    assert robot_record(PAPER) == robot_record(load_robot())  # stable
    assert robot_record(FOUR)["n_links"] == 4
    assert robot_record(FOUR)["geometry_sha256"] != robot_record(PAPER)["geometry_sha256"]
    heavier = PAPER_TEXT.replace("mass_kg = 0.25 ", "mass_kg = 0.26 ")
    assert heavier != PAPER_TEXT
    other = parse_robot(parse_toml(heavier, "<heavier>", ValueError), "<heavier>")
    assert robot_record(other)["geometry_sha256"] != robot_record(PAPER)["geometry_sha256"]
    renamed = PAPER_TEXT.replace("(paper default)", "(renamed)")
    same = parse_robot(parse_toml(renamed, "<renamed>", ValueError), "<renamed>")
    assert robot_record(same)["geometry_sha256"] == robot_record(PAPER)["geometry_sha256"]


def test_coefficients_of_another_robot_are_refused_naming_both_unless_allowed(tmp_path):
    path = _fit_file(tmp_path / "coefficients.json", PAPER)
    assert json.loads(path.read_text())["robot"]["n_links"] == 6
    assert set(read_coefficients(str(path), PAPER)) == {"straight", "turning"}
    with pytest.raises(CoefficientsError) as err:
        read_coefficients(str(path), FOUR)
    text = str(err.value)
    assert "N = 6" in text and "N = 4" in text and "four-link test robot" in text
    assert "--allow-other-robot" in text
    assert set(read_coefficients(str(path), FOUR, allow_other_robot=True)) == {"straight", "turning"}
    with pytest.raises(CoefficientsFileError, match="N = 4"):  # the planner's reader too
        read_coefficient_model(path, FOUR)
    assert read_coefficient_model(path, FOUR, allow_other_robot=True) is not None


def test_validate_refuses_a_6_link_fit_on_a_4_link_dataset_before_simulating(tmp_path, capsys):
    path = _fit_file(tmp_path / "coefficients.json", PAPER)
    folder = _dataset(tmp_path, FOUR_TEXT)
    assert main(["validate", str(path), str(folder), "--out", str(tmp_path / "v")]) == 2
    err = capsys.readouterr().err
    assert "fitted on robot" in err and "N = 6" in err and "N = 4" in err


def test_plan_refuses_coefficients_of_another_robot(tmp_path, capsys):
    path = _fit_file(tmp_path / "coefficients.json", FOUR)
    argv = ["plan", "tank_5_obstacles", "--coefficients-file", str(path), "--out",
            str(tmp_path / "plan")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "N = 4" in err and "N = 6" in err and "--allow-other-robot" in err


def test_a_dataset_without_its_robot_never_takes_the_working_folders(tmp_path, monkeypatch):
    folder = _dataset(tmp_path, None)
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    (elsewhere / "robot.toml").write_text(FOUR_TEXT)  # another robot where the user stands
    monkeypatch.chdir(elsewhere)
    with pytest.raises(DataError, match="dataset folder only") as err:
        load_dataset(folder)
    assert str(folder / "robot.toml") in str(err.value)
    manifest = folder / "manifest.toml"
    manifest.write_text(manifest.read_text().replace('robot = "robot.toml"\n', ""))
    with pytest.raises(DataError, match="names no robot file"):
        load_dataset(folder)


def test_a_dataset_names_a_bundled_robot_or_holds_its_own(tmp_path, monkeypatch):
    folder = _dataset(tmp_path, FOUR_TEXT)
    manifest = folder / "manifest.toml"
    manifest.write_text(manifest.read_text().replace('robot = "robot.toml"\n', ""))
    assert load_dataset(folder).robot.n_links == 4  # no name: the folder's robot.toml
    manifest.write_text('robot = "servo_robot.toml"\n' + manifest.read_text())
    monkeypatch.chdir(tmp_path)
    (tmp_path / "servo_robot.toml").write_text(FOUR_TEXT)  # not taken: bundled means bundled
    robot = load_dataset(folder).robot
    assert robot.n_links == 6 and robot.joint_model.name == "servo"
