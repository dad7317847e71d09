"""A user's own package extends eelbot through entry points: a fluid law, a transport, an
estimator and a subcommand, each one file outside eelbot, with no list edited (issue 30).

The package is "installed" as pip would: a ``*.dist-info`` folder with ``entry_points.txt`` and
the module beside it, in a temporary folder on ``sys.path`` (the ``install_distribution`` fixture
of conftest.py). The registries are emptied of
plug-ins for the test and restored after it.
"""

import logging
import sys
import types

import numpy as np
import pytest

from eelhost import cli
from eelhost.commands import COMMANDS
from eelhost.estimation.methods import ESTIMATORS, FitProblem, run_fit
from eelhost.link import open_link
from eelhost.link.uri import TRANSPORTS
from eelhost.wire import protocol
from eelsim.fluid import FLUID_LAWS, candidate_laws
from eelsim.guidance import GUIDANCE_LAWS
from eelsim.joints import JOINT_MODELS

PLUGIN = '''
"""Mine: a toy fluid law, transport, estimator and subcommand, registered from outside eelbot."""
from typing import ClassVar

from eelhost.commands import COMMANDS
from eelhost.estimation.methods import ESTIMATORS
from eelhost.estimation.optimise import FitResult
from eelhost.link.base import Link, WallClock
from eelhost.link.serial_transport import SerialTransport
from eelhost.link.uri import Port, TransportScheme
from eelsim.fluid import HydroCoefficients
from eelsim.fluid.morison import MorisonLaw


class StickyCoefficients(HydroCoefficients):
    """The Morison coefficients, under the sticky law's name."""

    law_name: ClassVar[str] = "sticky"


class StickyLaw(MorisonLaw):
    """Morison's forces under another name: water a user adds."""

    name: ClassVar[str] = "sticky"
    coefficients = StickyCoefficients
    description = "Morison's drag, a user's own law"


STICKY = StickyLaw()

LOOPBACK = TransportScheme(
    "loopback", (), "", lambda u, robot, clock: Link(SerialTransport("loop://"),
                                                    clock or WallClock()),
    lambda: [Port("loopback://", "bytes sent come back")], "loopback://",
    description="bytes sent come back (a user's transport)")


@ESTIMATORS.add("start-only", "return the start, fitting nothing (a user's estimator)")
def start_only(problem):
    values = problem.start
    fitness = float(problem.evaluator.fitness(values[None, :])[0])
    return FitResult("start-only", problem.evaluator.space, values, fitness, [], 1)


@COMMANDS.add("hello", "say hello (a user's subcommand)")
def add_parser(sub):
    p = sub.add_parser("hello", help=COMMANDS.description("hello"))
    p.add_argument("--name", default="eel")
    p.set_defaults(run=lambda args: print(f"hello {args.name}") or 0)
'''

BROKEN = "def add_parser(sub):\n    raise RuntimeError('this plug-in has a bug')\n"

REGISTRIES = (FLUID_LAWS, JOINT_MODELS, GUIDANCE_LAWS, TRANSPORTS, ESTIMATORS, COMMANDS)


@pytest.fixture
def installed(tmp_path, monkeypatch, install_distribution, registries_afresh):
    """The user's package and a broken one installed; every registry loads plug-ins afresh."""
    install_distribution("mine", {
        "eelbot.fluid_laws": {"sticky": "mine_plugin:STICKY"},
        "eelbot.transports": {"loopback": "mine_plugin:LOOPBACK"},
        "eelbot.estimators": {"start-only": "mine_plugin:start_only"},
        "eelbot.commands": {"hello": "mine_plugin:add_parser"},
    }, {"mine_plugin": PLUGIN})
    install_distribution("broken", {
        "eelbot.commands": {"oops": "broken_plugin:add_parser", "gone": "nowhere_at_all:x"},
    }, {"broken_plugin": "from eelhost.commands import COMMANDS\n\n"
        "@COMMANDS.add('oops', 'a command whose parser fails')\n" + BROKEN})
    registries_afresh(*REGISTRIES)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in ("mine_plugin", "broken_plugin"):
        sys.modules.pop(name, None)


def help_of(capsys, *argv):
    with pytest.raises(SystemExit):
        cli.main([*argv, "--help"])
    return capsys.readouterr().out


def test_a_users_law_transport_estimator_and_command_reach_the_cli(installed, capsys, caplog):
    with caplog.at_level(logging.WARNING):
        top = help_of(capsys)
    assert "hello" in top and "say hello (a user's subcommand)" in top
    assert cli.main(["hello", "--name", "conger"]) == 0
    assert capsys.readouterr().out == "hello conger\n"

    estimate = help_of(capsys, "estimate")
    assert "start-only" in estimate and "fitting nothing" in estimate
    report = help_of(capsys, "report")
    assert "start-only" in report
    dataset = help_of(capsys, "dataset")
    assert "sticky" in dataset.split("--fluid-law")[1].split("--")[0]

    assert cli.main(["ports"]) == 0
    ports = capsys.readouterr().out
    assert "loopback://\tbytes sent come back" in ports and "loopback://" in ports.splitlines()[-1]


def test_the_users_plug_ins_work_where_the_built_ins_do(installed):
    law = FLUID_LAWS["sticky"]
    assert law.coefficient_names == ("C_f", "C_d", "C_a", "C_m")
    assert "sticky" not in candidate_laws()  # a new law is compared only when it says so
    morison = FLUID_LAWS["morison"]
    args = ([0.03], [0.02], [0.01], [0.01, 0.8, 0.6, 0.01], 1000.0)
    assert np.allclose(law.link_coefficients(*args).mu_n, morison.link_coefficients(*args).mu_n)

    link = open_link("loopback://")
    link.send(protocol.SetOffset(0.25))
    assert link.poll() == [protocol.SetOffset(0.25)]

    space = types.SimpleNamespace(current=False)
    evaluator = types.SimpleNamespace(space=space, fitness=lambda v: np.sum(v * v, axis=1))
    problem = FitProblem(evaluator, types.SimpleNamespace(method="start-only"),
                         np.array([0.5, 1.0]))
    result = run_fit(problem)
    assert result.method == "start-only" and result.fitness == pytest.approx(1.25)


def test_a_broken_plug_in_is_named_and_the_cli_still_works(installed, capsys, caplog):
    with caplog.at_level(logging.WARNING):
        top = help_of(capsys)
    assert "hello" in top and "oops" not in top and "gone" not in top
    assert "plug-in 'oops = broken_plugin:add_parser' (eelbot.commands) not loaded: " \
           "RuntimeError: this plug-in has a bug" in caplog.text
    assert "plug-in 'gone = nowhere_at_all:x' (eelbot.commands) not loaded: " \
           "ModuleNotFoundError" in caplog.text
    assert cli.main(["hello"]) == 0


def test_an_unknown_choice_names_the_registered_ones(installed, capsys):
    assert cli.main(["estimate", "nowhere", "--method", "simplex"]) == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'simplex'" in err and "start-only" in err
    assert cli.main(["ports"]) == 0 and "loopback" in capsys.readouterr().out
    with pytest.raises(ValueError, match="unknown scheme 'tcp' .expected .*loopback"):
        open_link("tcp://robot")


def test_in_a_fresh_process_the_installed_package_reaches_the_cli(tmp_path, install_distribution):
    """No registry reset: what a user gets after ``pip install`` of their package."""
    import os
    import subprocess

    install_distribution("mine", {"eelbot.commands": {"hello": "mine_plugin:add_parser"},
                                  "eelbot.estimators": {"start-only": "mine_plugin:start_only"}},
                         {"mine_plugin": PLUGIN})
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(tmp_path), *filter(None, [os.environ.get("PYTHONPATH")])])}

    def eelbot(*argv):
        return subprocess.run([sys.executable, "-m", "eelhost", *argv], env=env,
                              capture_output=True, text=True, timeout=300)

    hello = eelbot("hello", "--name", "moray")
    assert hello.returncode == 0 and hello.stdout == "hello moray\n" and hello.stderr == ""
    method = eelbot("estimate", "--help")
    assert "start-only" in method.stdout.split("--method")[1]
