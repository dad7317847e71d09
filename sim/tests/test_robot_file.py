import math
import tomllib
from importlib import resources

import pytest

from eelsim.robot import RobotFileError, load_robot


def bundled_text():
    return resources.files("eelsim.data").joinpath("paper_robot.toml").read_text()


def write(tmp_path, text):
    p = tmp_path / "robot.toml"
    p.write_text(text)
    return p


def test_bundled_paper_robot_has_six_links_and_a_body_length_near_064_m():
    robot = load_robot()
    assert robot.n_links == 6
    assert robot.body_length_m() == pytest.approx(0.64, abs=0.01)
    assert robot.hydrodynamics.C_d == 0.776


def test_every_assumed_value_of_the_default_robot_is_marked_with_a_reason():
    robot = load_robot()
    for key in (
        "link.half_axis_vertical_m",
        "link.half_axis_horizontal_m",
        "link.mass_kg",
        "joints.kp_nm_per_rad",
        "joints.kd_nms_per_rad",
    ):
        assert robot.assumptions.get(key, "").strip(), key


def test_file_round_trip_loads_the_same_robot(tmp_path):
    assert load_robot(write(tmp_path, bundled_text())) == load_robot()


@pytest.mark.parametrize(
    ("edit", "key", "what"),
    [
        (lambda d: d["link"].update(colour="red"), "link.colour", "unknown key"),
        (lambda d: d.update(wings=2), "wings", "unknown key"),
        (lambda d: d["joints"].update(kp_gain=1.0), "joints.kp_gain", "unknown key"),
        (lambda d: d["link"].update(mass_kg="heavy"), "link.mass_kg", "valid number"),
        (lambda d: d["link"].update(mass_kg=-0.25), "link.mass_kg", "greater than 0"),
        (lambda d: d.update(n_links=1), "n_links", "greater than or equal to 2"),
        (lambda d: d["hydrodynamics"].update(C_d=math.nan), "hydrodynamics.C_d", "finite"),
        (lambda d: d["link"].update(half_length_m=math.inf), "link.half_length_m", "finite"),
        (lambda d: d.update(head={"mass_kg": 0.3, "fins": 2}), "head.fins", "unknown key"),
        (lambda d: d["hydrodynamics"].pop("C_a"), "hydrodynamics.C_a", "Field required"),
        (lambda d: d["assumptions"].update({"link.colour": "why"}), "assumptions", "names no key"),
        (lambda d: d["hydrodynamics"].update(law="potential"), "hydrodynamics",
         "unknown fluid law 'potential'; known laws: "),
        (lambda d: d["joints"].update(model="stepper"), "joints",
         "model must name a joint model (pd, pd_limited, servo), got 'stepper'"),
        (lambda d: d["joints"].update(position_gain_1_s=30.0), "joints.position_gain_1_s",
         "unknown key"),
        (lambda d: d["hydrodynamics"].update(C_x=1.0), "hydrodynamics.C_x", "unknown key"),
    ],
)
def test_bad_robot_file_is_refused_naming_the_file_and_the_key(tmp_path, edit, key, what):
    data = tomllib.loads(bundled_text())
    edit(data)
    path = write(tmp_path, _dump(data))
    with pytest.raises(RobotFileError) as info:
        load_robot(path)
    msg = str(info.value)
    assert str(path) in msg
    assert key in msg
    assert what in msg


def test_a_robot_file_without_a_fluid_law_gets_the_papers_morison_law(tmp_path):
    data = tomllib.loads(bundled_text())
    assert "law" not in data["hydrodynamics"]
    robot = load_robot()
    assert robot.fluid_law.name == "morison"
    assert robot.fluid_law.coefficient_names == ("C_f", "C_d", "C_a", "C_m")
    data["hydrodynamics"]["law"] = "morison"
    assert load_robot(write(tmp_path, _dump(data))) == robot


def test_yaw_inertia_defaults_to_a_slender_rods_unless_given():
    link = load_robot().link
    assert link.yaw_inertia_or_default_kg_m2() == pytest.approx(
        link.mass_kg * link.half_length_m**2 / 3.0)
    given = link.model_copy(update={"yaw_inertia_kg_m2": 2e-4})
    assert given.yaw_inertia_or_default_kg_m2() == 2e-4


def test_unreadable_and_malformed_files_are_refused_with_the_path(tmp_path):
    with pytest.raises(RobotFileError, match="cannot read"):
        load_robot(tmp_path / "missing.toml")
    with pytest.raises(RobotFileError, match="not valid TOML"):
        load_robot(write(tmp_path, "n_links = = 3"))


def _dump(data, prefix=""):
    """Tiny TOML writer for the test's edited dictionaries (floats incl. nan/inf)."""

    def val(v):
        if isinstance(v, str):
            return '"' + v + '"'
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float) and math.isnan(v):
            return "nan"
        if isinstance(v, float) and math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)

    lines, tables = [], []
    for k, v in data.items():
        (tables if isinstance(v, dict) else lines).append((k, v))
    out = [f'"{k}" = {val(v)}' for k, v in lines]
    for k, v in tables:
        out.append(f"[{prefix}{k}]")
        out += [f'"{kk}" = {val(vv)}' for kk, vv in v.items() if not isinstance(vv, dict)]
    return "\n".join(out) + "\n"
