"""``--coefficients`` follows the robot file's fluid law: by name or all in the law's order, for
any law (the bundled linear_quadratic has six), with errors naming the law's coefficients."""

import argparse
from importlib import resources

import pytest

from eelhost.cli import main
from eelhost.commands.common import OptionError, robot_and_coefficients
from eelsim.fluid import FLUID_LAWS, LinearQuadraticCoefficients

LINEAR_QUADRATIC_TABLE = """[hydrodynamics]
law = "linear_quadratic"
C_f_lin = 0.008
C_d_lin = 0.776
C_f_quad = 0.02
C_d_quad = 1.2
C_a = 0.618
C_m = 0.007
"""


@pytest.fixture
def lq_robot(tmp_path):
    text = resources.files("eelsim.data").joinpath("paper_robot.toml").read_text()
    start = text.index("[hydrodynamics]")
    end = text.index("\n[", start)
    path = tmp_path / "lq_robot.toml"
    path.write_text(text[:start] + LINEAR_QUADRATIC_TABLE + text[end:])
    return str(path)


def chosen(robot, text):
    return robot_and_coefficients(argparse.Namespace(robot=robot, coefficients=text))[1]


def test_a_six_coefficient_law_takes_its_coefficients_by_name_or_in_order(lq_robot):
    by_name = chosen(lq_robot, "C_d_quad=0.9,C_a=1.0")
    assert by_name == LinearQuadraticCoefficients(C_f_lin=0.008, C_d_lin=0.776, C_f_quad=0.02,
                                                  C_d_quad=0.9, C_a=1.0, C_m=0.007)
    in_order = chosen(lq_robot, "0.01,0.7,0.03,0.9,1.0,0.002")
    assert in_order.as_array().tolist() == [0.01, 0.7, 0.03, 0.9, 1.0, 0.002]
    assert chosen(lq_robot, None) == chosen(lq_robot, "C_m=0.007")  # the robot file's


def test_the_paper_law_takes_a_subset_by_name():
    c = chosen(None, "C_d=0.8,C_a=1.0")
    assert (c.C_f, c.C_d, c.C_a, c.C_m) == (0.008, 0.8, 1.0, 0.007)


@pytest.mark.parametrize("text, message", [
    ("0.008,0.776,0.618,0.007", "expected 6 numbers in order, got 4 .*the linear_quadratic "
                                "law's coefficients are C_f_lin, C_d_lin, C_f_quad, C_d_quad, "
                                "C_a, C_m"),
    ("C_d=0.8", "'C_d' is not a coefficient of the linear_quadratic law .*C_f_lin, C_d_lin"),
    ("C_a=1,C_a=2", "C_a given twice"),
    ("C_a=1,0.5", "give all as NAME=VALUE or all as numbers"),
    ("C_a=wet", "C_a='wet' is not a number"),
])
def test_a_wrong_name_or_count_is_refused_naming_the_laws_coefficients(lq_robot, text, message):
    with pytest.raises(OptionError, match=f"--coefficients: {message}"):
        chosen(lq_robot, text)


def test_on_the_command_line_a_wrong_count_is_a_usage_error_naming_the_coefficients(
        lq_robot, capsys):
    assert main(["speeds", "--robot", lq_robot, "--coefficients", "1,2,3,4"]) == 2
    err = capsys.readouterr().err
    assert "--coefficients" in err and "C_f_lin, C_d_lin, C_f_quad, C_d_quad, C_a, C_m" in err
    assert main(["speeds", "--coefficients", "C_d=-1"]) == 2
    assert "--coefficients: C_d should be greater than or equal to 0" in capsys.readouterr().err


@pytest.mark.parametrize("name", list(FLUID_LAWS))
def test_every_registered_law_reads_its_coefficients_back_by_name_and_in_order(name):
    record = FLUID_LAWS[name].coefficients
    middle = record.from_array(FLUID_LAWS[name].bounds.mean(axis=1))
    values = [float(v) for v in middle.as_array()]
    text = ",".join(f"{key}={v!r}" for key, v in zip(record.names(), values, strict=True))
    assert record.from_text(text) == middle
    assert record.from_text(",".join(repr(v) for v in values)) == middle


def test_the_virtual_robots_water_takes_coefficients_by_name_too(lq_robot):
    from eelhost.link.sim_transport import _in_the_water
    from eelhost.link.uri import LinkURIError, parse_link_uri
    from eelsim.robot import load_robot

    robot = load_robot(lq_robot)
    water = _in_the_water(parse_link_uri("sim://?coefficients=C_a=0.9,C_m=0.01"), robot)
    assert water.hydrodynamics == chosen(lq_robot, "C_a=0.9,C_m=0.01")
    with pytest.raises(LinkURIError, match="coefficients='C_x=1'.*not a coefficient of the "
                                           "linear_quadratic law"):
        _in_the_water(parse_link_uri("sim://?coefficients=C_x=1"), robot)
