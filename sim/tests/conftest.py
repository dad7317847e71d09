import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))  # the test oracles live beside the tests

from eelsim.model import SwimmerModel  # noqa: E402
from eelsim.robot import HydroCoefficients, load_robot  # noqa: E402


@pytest.fixture(scope="session")
def robot():
    return load_robot()


@pytest.fixture(scope="session")
def model(robot):
    return SwimmerModel.from_robot(robot)


@pytest.fixture(scope="session")
def vacuum_model(robot):
    return SwimmerModel.from_robot(robot, HydroCoefficients(C_f=0.0, C_d=0.0, C_a=0.0, C_m=0.0))
