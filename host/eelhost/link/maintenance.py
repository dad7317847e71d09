"""Maintenance over the link: who the robot is, its settings and its health.

:class:`Maintenance` asks and waits over one :class:`eelhost.link.base.Link` (any transport: the
robot's serial port, ``sim://``): Hello for the Version, GetSetting / SetSetting / SaveSettings /
DefaultSettings for the settings (docs/firmware.md, "Settings"), GetStatus for the health counters
(docs/firmware.md, "Messages"). It waits on the link's clock, so over ``sim://`` the virtual robot
runs while it waits and nothing here reads the wall clock. ``eelbot robot`` is built on it.

The robot's settings are named as in the settings table (``kp_nm_per_rad``); a per-joint setting
(``trim_us``) has one value per joint, joint 1 (the tail) first.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from eelhost.errors import UserError
from eelhost.link.base import Link
from eelhost.wire import protocol

log = logging.getLogger(__name__)

__all__ = [
    "Health",
    "Maintenance",
    "RobotAnswerError",
    "SettingError",
    "parse_assignment",
    "setting_info",
]

_A = TypeVar("_A")

#: How often the link is read while waiting for an answer, s.
POLL_S = 0.005


class RobotAnswerError(UserError, RuntimeError):
    """The robot refused a request or did not answer it in time; the message says which."""


class SettingError(UserError, ValueError):
    """A setting name, joint or value that the robot would not take; the message names it."""


def setting_info(name: str) -> protocol.SettingInfo:
    """The settings-table entry of a setting, by name.

    Raises
    ------
    SettingError
        For a name the table does not have (the message lists the names).
    """
    info = protocol.SETTINGS.get(name)
    if info is None:
        raise SettingError(f"no setting {name!r} (settings: {', '.join(protocol.SETTINGS)})")
    return info


def parse_assignment(text: str) -> list[tuple[str, int, float]]:
    """Parse ``NAME=VALUE``, ``NAME.J=VALUE`` or ``NAME=V1,V2,...`` into (name, index, value).

    ``J`` is a joint number, 1 (the tail) to N_JOINTS; a per-joint setting given without one takes
    either one value for every joint or N_JOINTS values, joint 1 first.

    Parameters
    ----------
    text : str
        The assignment, as typed after ``--set``.

    Returns
    -------
    list of (str, int, float)
        Setting name, index on the wire (joint J is index J - 1), value: one element per
        SetSetting to send.

    Raises
    ------
    SettingError
        Naming the part of ``text`` that is wrong (no ``=``, unknown name, joint out of range,
        a value that is not a number or that the robot would refuse).
    """
    name, sep, raw = text.partition("=")
    if not sep:
        raise SettingError(f"{text!r}: expected NAME=VALUE (or NAME.J=VALUE for joint J)")
    name = name.strip()
    joint: int | None = None
    if "." in name:
        name, _, joint_text = name.partition(".")
        try:
            joint = int(joint_text)
        except ValueError:
            raise SettingError(f"{text!r}: joint {joint_text!r} is not a whole number") from None
    try:
        info = setting_info(name)
    except SettingError as err:
        raise SettingError(f"{text!r}: {err}") from None
    try:
        values = [float(v) for v in raw.split(",")]
    except ValueError:
        raise SettingError(f"{text!r}: {raw!r} is not a number (or numbers, comma-separated)") from None
    if joint is not None:
        if info.count == 1:
            raise SettingError(f"{text!r}: {name} is one value, not one per joint")
        if not 1 <= joint <= info.count:
            raise SettingError(f"{text!r}: joint {joint} outside 1..{info.count}")
        if len(values) != 1:
            raise SettingError(f"{text!r}: one value for joint {joint}")
        indices = [joint - 1]
    elif len(values) == 1:
        indices = list(range(info.count))
        values = values * info.count
    elif len(values) == info.count:
        indices = list(range(info.count))
    else:
        raise SettingError(f"{text!r}: {name} takes 1 or {info.count} values, got {len(values)}")
    out = []
    for index, value in zip(indices, values, strict=True):
        try:
            info.check(value, index)
        except ValueError as err:
            raise SettingError(f"{text!r}: {err}") from None
        out.append((name, index, value))
    return out


@dataclass(frozen=True)
class Health:
    """What the robot says about itself: its Version and a Status, with what they mean.

    Attributes
    ----------
    version : protocol.Version
    status : protocol.Status
    """

    version: protocol.Version
    status: protocol.Status

    @property
    def joint_feedback(self) -> bool:
        """Whether the robot measures its joint angles (analog-feedback servos) and runs the PD."""
        return bool(self.status.flags & protocol.Flags.JOINT_FEEDBACK)

    @property
    def battery_sense(self) -> bool:
        """Whether a battery divider is fitted (``battery_v`` is measured)."""
        return bool(self.status.flags & protocol.Flags.BATTERY_SENSE)

    def counters(self) -> dict[str, int]:
        """The link and health counters of the Status, by name."""
        names = (
            "frames_ok", "bad_cobs", "bad_short", "bad_oversize", "bad_crc", "bad_schema",
            "bad_unknown_id", "bad_length", "bad_crc32", "bad_direction", "duplicates", "lost",
            "tx_dropped", "resets", "control_late_max_us",
        )  # fmt: skip
        return {name: int(getattr(self.status, name)) for name in names}

    def lines(self) -> list[str]:
        """The report ``eelbot robot status`` prints, one fact a line."""
        s, v = self.status, self.version
        reset = protocol.ResetFlags(s.reset_flags)
        reset_text = "|".join(f.name or "" for f in protocol.ResetFlags if f in reset) or (
            "none (cleared by the bootloader)"
        )
        flags = protocol.Flags(s.flags)
        flag_text = "|".join(f.name or "" for f in protocol.Flags if f in flags) or "none"
        battery = f"{s.battery_v:.2f} V" if self.battery_sense else "not measured (no divider)"
        feedback = (
            "analog feedback: joint angles measured, PD on the robot"
            if self.joint_feedback
            else "none: servos commanded open loop (no measured angles)"
        )
        out = [
            f"firmware {v.firmware_major}.{v.firmware_minor}, protocol {v.protocol_version}, "
            f"schema 0x{v.schema_hash:04X}, settings 0x{v.settings_version:04X}, "
            f"{v.n_joints} joints, radio id {v.radio_id}",
            f"state: {_name(protocol.State, s.state)}",
            f"joint feedback: {feedback}",
            f"battery: {battery}",
            f"reset cause: {reset_text}; resets since power-on: {s.resets}",
            f"settings from: {_name(protocol.SettingsSource, s.settings_source)}",
            f"flags: {flag_text}",
        ]
        out += [f"{name}: {value}" for name, value in self.counters().items()]
        return out


def _name(enum: type[protocol.IntEnum], value: int) -> str:
    try:
        return enum(value).name
    except ValueError:
        return f"unknown ({value})"


class Maintenance:
    """Requests to the robot over a link, each waited for on the link's clock.

    Parameters
    ----------
    link : Link
        Opened.
    timeout_s : float
        How long to wait for an answer (resending commands as the link does) before giving up.
    """

    def __init__(self, link: Link, timeout_s: float = 2.0) -> None:
        self.link = link
        self.timeout_s = timeout_s

    def _wait_for(self, what: str, pick: Callable[[protocol.Message], _A | None]) -> _A:
        clock = self.link.clock
        deadline = clock.now() + self.timeout_s
        while True:
            for msg in self.link.poll():
                got = pick(msg)
                if got is not None:
                    return got
            if clock.now() >= deadline:
                raise RobotAnswerError(
                    f"no {what} from the robot within {self.timeout_s:g} s over "
                    f"{self.link.transport.description}"
                )
            clock.wait_until(clock.now() + POLL_S)

    def _command(self, message: protocol.Message) -> None:
        """Send a command and wait for its Ack; a Refuse becomes a RobotAnswerError."""
        seq = self.link.send(message, want_ack=True)
        name = type(message).__name__
        clock = self.link.clock
        deadline = clock.now() + self.timeout_s
        while True:
            self.link.poll()
            outcome = self.link.outcome(seq)
            if outcome == "ack":
                return
            if outcome == "refused":
                raise RobotAnswerError(f"the robot refused {name}: {self._refusal(seq)}")
            if outcome == "lost" or clock.now() >= deadline:
                raise RobotAnswerError(
                    f"{name} not acknowledged within {self.timeout_s:g} s over "
                    f"{self.link.transport.description}"
                )
            clock.wait_until(clock.now() + POLL_S)

    def _refusal(self, seq: int) -> str:
        reason = self.link.refusal(seq)
        if reason is None:
            return "no reason given"
        return {
            protocol.RefuseReason.NOT_WHILE_RUNNING: "not while it undulates (stop it first)",
            protocol.RefuseReason.STORAGE_FAILED: "the EEPROM did not read back what was written",
            protocol.RefuseReason.SETTINGS_LOST: "SETTINGS_LOST: its stored settings were lost "
            "and it runs on the defaults; acknowledge with `eelbot robot config --defaults "
            "[--set NAME=VALUE ...] --save` (docs/firmware.md, 'Settings in the EEPROM')",
        }.get(reason, reason.name)

    def hello(self) -> protocol.Version:
        """Ask who the robot is (also resynchronises its sequence check)."""
        self.link.send(protocol.Hello())
        return self._wait_for(
            "Version", lambda m: m if isinstance(m, protocol.Version) else None
        )

    def health(self) -> Health:
        """The robot's Version and a fresh Status."""
        version = self.hello()
        self.link.send(protocol.GetStatus())
        status = self._wait_for("Status", lambda m: m if isinstance(m, protocol.Status) else None)
        return Health(version, status)

    def get(self, name: str) -> list[float]:
        """A setting's values as the robot holds them (one per joint for a per-joint setting)."""
        info = setting_info(name)
        values = []
        for index in range(info.count):
            self.link.send(protocol.GetSetting(info.key, index))

            def pick(m: protocol.Message, index: int = index) -> float | None:
                if isinstance(m, protocol.Setting) and (m.key, m.index) == (info.key, index):
                    return float(m.value)
                return None

            values.append(self._wait_for(f"Setting {name}[{index}]", pick))
        return values

    def set(self, name: str, index: int, value: float) -> None:
        """Change one setting (one joint's element) in the robot's RAM; :meth:`save` stores it."""
        info = setting_info(name)
        try:
            info.check(value, index)
        except ValueError as err:
            raise SettingError(str(err)) from None
        self._command(protocol.SetSetting(info.key, index, value))

    def save(self) -> None:
        """Write the settings in use to the robot's EEPROM (acknowledged once read back)."""
        self._command(protocol.SaveSettings())

    def defaults(self) -> None:
        """Put every setting back to its default in the robot's RAM."""
        self._command(protocol.DefaultSettings())

    def start(self) -> None:
        """Start undulating (refused with the settings lost, or on a low battery)."""
        self._command(protocol.Start())

    def stop(self) -> None:
        """Stop undulating (settings can only change while the robot does not undulate)."""
        self._command(protocol.Stop())
