"""Options and markers of the firmware-, processor- and hardware-in-the-loop tests.

``--port PORT`` (or the environment variable ``EELBOT_PORT``) runs ``test_hardware.py`` against a
real robot; ``--rig FILE`` names its rig file (default ``hil_tests/rig_default.toml``). Without a
port the hardware tests are skipped, with a message that says how to run them.
"""

import os
import tomllib
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
HOW_TO_RUN = (
    "no robot port given: run `pytest hil_tests -m hardware --port /dev/ttyUSB0` "
    "(or set EELBOT_PORT=/dev/ttyUSB0; --rig FILE for another rig file than "
    "hil_tests/rig_default.toml)"
)


def pytest_addoption(parser):
    group = parser.getgroup("eelbot hardware in the loop")
    group.addoption("--port", default=None, help="serial port of a real robot (or EELBOT_PORT)")
    group.addoption(
        "--rig", default=str(HERE / "rig_default.toml"), help="rig file of the hardware tests"
    )


def _rig(config) -> dict:
    rig = tomllib.loads(Path(config.getoption("--rig")).read_text())
    port = config.getoption("--port") or os.environ.get("EELBOT_PORT") or rig.get("port", "")
    rig["port"] = port
    return rig


def pytest_collection_modifyitems(config, items):
    if _rig(config)["port"]:
        return
    skip = pytest.mark.skip(reason=HOW_TO_RUN)
    for item in items:
        if "hardware" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def rig(pytestconfig) -> dict:
    """The rig description, with the port resolved from --port, EELBOT_PORT or the file."""
    return _rig(pytestconfig)
