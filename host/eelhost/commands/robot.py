"""``eelbot robot``: the robot's settings, trims and health over its link (serial:// or sim://).

- ``eelbot robot config --link URI [--defaults] [--set NAME=VALUE ...] [--save] [--get NAME ...]``
- ``eelbot robot trim --link URI``: interactive trim calibration (:mod:`eelhost.commands.robot_trim`)
- ``eelbot robot status --link URI``: health counters, battery, reset cause, feedback mode

The settings and messages are those of docs/firmware.md ("Settings", "Messages").
"""

from __future__ import annotations

import argparse

from eelhost.commands import COMMANDS, robot_trim
from eelhost.commands.link_options import add_link_options, resolve_link_options
from eelhost.link.base import Link
from eelhost.link.maintenance import Maintenance, parse_assignment, setting_info
from eelhost.link.uri import open_link
from eelhost.wire import protocol
from eelsim.robot import load_robot

LINK_NOTE = ("required; sim://?feedback=1&battery=7.4 gives the virtual robot analog-feedback "
             "servos and a battery (docs/host.md)")


@COMMANDS.add("robot", "the robot's settings, servo trims and health, over its link")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand and its own subcommands."""
    p = sub.add_parser(
        "robot",
        help=COMMANDS.description("robot"),
        description="Talk to the robot (or the virtual robot) over its link: read and change its "
        "settings (docs/firmware.md, 'Settings'), calibrate the servo trims, print its health.",
    )
    jobs = p.add_subparsers(dest="robot_command", metavar="JOB", required=True)

    c = jobs.add_parser(
        "config",
        help="get, set and save settings",
        description="Settings are applied in this order: --defaults, every --set, --save, then "
        "every --get is read back. Without --get, --set, --save or --defaults every setting is "
        "printed. NAME is a name of the settings table (docs/firmware.md); a per-joint setting "
        "takes NAME.J=VALUE for joint J (1 = tail), or one value for all joints, or one per "
        "joint: trim_us=0,10,-20,0,5. Settings change only while the robot does not undulate. "
        "Example: eelbot robot config --link sim://?speed=0 --set kp_nm_per_rad=2 "
        "--set trim_us.2=-40 --save --get trim_us",
    )
    _link_arguments(c)
    c.add_argument("--get", action="append", default=[], metavar="NAME", help="print a setting")
    c.add_argument(
        "--set", action="append", default=[], metavar="NAME=VALUE", help="change a setting (RAM)"
    )
    c.add_argument("--save", action="store_true", help="store the settings in the EEPROM")
    c.add_argument(
        "--defaults", action="store_true", help="put every setting back to its default first"
    )
    c.set_defaults(run=run_config)

    t = jobs.add_parser(
        "trim",
        help="calibrate the servo trims interactively",
        description=robot_trim.DESCRIPTION,
    )
    _link_arguments(t)
    t.set_defaults(run=robot_trim.run)

    s = jobs.add_parser(
        "status",
        help="print the robot's health: counters, battery, reset cause, joint feedback",
        description="Ask the robot for its Version and a Status and print them: firmware and "
        "schema, state, whether it has joint feedback (analog-feedback servos, PD on the robot), "
        "battery voltage, why it last reset, where its settings came from, and every link and "
        "health counter.",
    )
    _link_arguments(s)
    s.set_defaults(run=run_status)


def _link_arguments(p: argparse.ArgumentParser) -> None:
    add_link_options(p, LINK_NOTE,
                     "the robot file of a sim:// robot (default: the bundled paper robot)")
    p.add_argument(
        "--timeout", type=float, default=2.0, help="seconds to wait for each answer (2)"
    )


def open_maintenance(args: argparse.Namespace) -> tuple[Link, Maintenance]:
    """The link of ``--link`` and a :class:`Maintenance` session on it, the robot said hello."""
    resolve_link_options(args, required="to talk to the robot")
    robot = load_robot(args.robot_file) if args.robot_file is not None else None
    link = open_link(args.link, robot=robot)
    session = Maintenance(link, timeout_s=args.timeout)
    session.hello()
    return link, session


def format_setting(name: str, values: list[float]) -> str:
    """``name = v`` (``v1, v2, ...`` for a per-joint setting), whole numbers without decimals."""
    info = setting_info(name)

    def one(v: float) -> str:
        return str(int(v)) if info.wire_type != "f32" else f"{v:.7g}"

    return f"{name} = {', '.join(one(v) for v in values)}"


def run_config(args: argparse.Namespace) -> int:
    """Run ``eelbot robot config``."""
    assignments = [a for text in args.set for a in parse_assignment(text)]
    for name in args.get:
        setting_info(name)  # a bad name fails before anything changes on the robot
    link, session = open_maintenance(args)
    try:
        if args.defaults:
            session.defaults()
            print("defaults restored (in RAM)")
        for name, index, value in assignments:
            session.set(name, index, value)
        if assignments:
            print(f"{len(assignments)} value(s) set (in RAM)")
        if args.save:
            session.save()
            print("settings saved to the EEPROM")
        names = args.get
        if not (names or assignments or args.save or args.defaults):
            names = list(protocol.SETTINGS)
        for name in names:
            print(format_setting(name, session.get(name)))
    finally:
        link.close()
    return 0


def run_status(args: argparse.Namespace) -> int:
    """Run ``eelbot robot status``."""
    link, session = open_maintenance(args)
    try:
        health = session.health()
    finally:
        link.close()
    for line in health.lines():
        print(line)
    return 0
