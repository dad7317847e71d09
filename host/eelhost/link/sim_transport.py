"""The ``sim://`` transport: the host's end of a simulated radio (the virtual robot, lockstep runs).

:class:`SimTransport` writes the host's bytes into the uplink of a radio model
(:class:`eelhost.xil.radio.RadioChannel`) and reads what the downlink has delivered, both stamped
with a simulated clock. It is the transport of ``sim://`` (the virtual robot,
:class:`eelhost.xil.virtual_robot.VirtualRobot`) and of the firmware-in-the-loop runs
(:func:`eelhost.xil.lockstep.run_lockstep`): one host session, :class:`eelhost.link.base.Link`,
over either.

``sim://?speed=10&seed=0`` parameters: ``speed`` (simulated seconds per wall second, 0 = as fast as
possible; default 1), ``seed``, ``radio`` (``xbee`` or ``ideal``), ``loss`` (byte loss
probability), ``drop=START:END`` (the link is down over that window, s; repeat or separate with
commas), ``start=x,y,heading_deg`` (where the robot starts in the virtual tank),
``current=speed,direction_deg``, ``feedback`` (1: analog-feedback servos, the robot measures its
joint angles and runs the PD itself; 0 by default), ``battery`` (volts of a battery behind the
robot's divider, measured by the firmware; none by default), ``coefficients=C_f,C_d,C_a,C_m``
(the water the virtual robot swims in: all in the order of the robot file's fluid law, or some
by name, ``coefficients=C_d=0.8,C_a=1.0``, the others the file's; by default the
robot file's ``[hydrodynamics]``: the host's model and the virtual tank's truth are then the same
numbers, docs/host.md "The virtual robot and replays"), ``eeprom=FILE`` (the robot's EEPROM kept in
FILE between invocations, so saved settings persist: ``eelbot robot config --link
sim://?eeprom=robot.eeprom --set trim_us.1=20 --save``; by default each sim:// robot is new).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from pydantic import ValidationError

from eelhost.link.base import Clock, Link, TransportError
from eelhost.link.uri import LinkURI, LinkURIError, Port, TransportScheme, register_transport
from eelhost.wire.limits import MAX_CURRENT_M_S
from eelsim.robot import Robot, load_robot
from eelsim.tomlfile import validation_message

if TYPE_CHECKING:
    from eelhost.xil.virtual_robot import VirtualRobot

__all__ = ["SimTransport"]


class ByteChannel(Protocol):
    """One direction of a simulated radio (:class:`eelhost.xil.radio.RadioChannel`)."""

    def send(self, t_us: int, data: bytes) -> None:
        """Hand bytes to the channel at ``t_us``."""
        ...

    def deliver_bytes(self, until_us: int) -> bytes:
        """The bytes that have arrived by ``until_us``."""
        ...


class SimTransport:
    """The host's end of a simulated radio.

    Parameters
    ----------
    uplink, downlink : RadioChannel
        Host -> robot and robot -> host.
    now_us : callable
        The simulated time, us (the clock of the host's :class:`~eelhost.link.base.Link`).
    link_down : callable, optional
        ``link_down(t_us)``: whether the link is down at that time (a drop window); never by
        default.
    robot : VirtualRobot, optional
        What is at the other end, for callers that need it (``sim://``); None in lockstep runs.
    """

    def __init__(
        self,
        uplink: ByteChannel,
        downlink: ByteChannel,
        now_us: Callable[[], int],
        link_down: Callable[[int], bool] | None = None,
        robot: VirtualRobot | None = None,
    ) -> None:
        self.uplink = uplink
        self.downlink = downlink
        self.robot = robot
        self.description = (
            "virtual robot (native firmware + twin)" if robot is not None else "simulated radio"
        )
        self._now_us = now_us
        self._link_down = link_down or (lambda _t_us: False)
        self._open = False

    @property
    def is_connected(self) -> bool:
        """Open, and no drop window has closed it (a dropped link stays down until reopened)."""
        if self._open and self._link_down(self._now_us()):
            self._open = False  # like a USB adapter that vanished: the host must reopen it
        return self._open

    def open(self) -> None:
        """Connect; fails inside a drop window, like a port that is not there."""
        if self._link_down(self._now_us()):
            raise TransportError("virtual link is down")
        self._open = True

    def close(self) -> None:
        """Disconnect (the virtual robot's EEPROM goes to its file, with ``eeprom=FILE``)."""
        self._open = False
        if self.robot is not None:
            self.robot.save_eeprom()

    def write(self, data: bytes) -> None:
        """Hand bytes to the uplink at the present time."""
        if not self.is_connected:
            raise TransportError("virtual link is down")
        self.uplink.send(self._now_us(), data)

    def read(self) -> bytes:
        """Bytes the downlink has delivered by now."""
        if not self.is_connected:
            raise TransportError("virtual link is down")
        return self.downlink.deliver_bytes(self._now_us())


def _open_sim(u: LinkURI, robot: Robot | None, clock: Clock | None) -> Link:
    """A link to a new virtual robot; its clock, not ``clock``, times the link."""
    vr = _virtual_robot(u, _in_the_water(u, robot or load_robot()))
    return Link(vr.transport(), vr.clock)


def _in_the_water(u: LinkURI, robot: Robot) -> Robot:
    """The robot with the URI's ``coefficients`` as its water (the robot file's without them)."""
    raw = u.one("coefficients")
    if raw is None:
        return robot
    by_name = "=" in raw  # C_d=0.8,C_a=1.0: the others the robot file's (from_text)
    values = None if by_name else u.numbers("coefficients", raw, None)
    law = type(robot.hydrodynamics)
    try:
        if values is None:
            return robot.with_coefficients(law.from_text(raw, robot.hydrodynamics))
        return robot.with_coefficients(law.from_array(values))
    except ValidationError as err:  # a value out of the law's range
        where = f"{u.text!r}: coefficients={raw!r}"
        raise LinkURIError(validation_message(where, err, f"{law.law_name} coefficients")) from None
    except ValueError as err:  # a wrong name or count; the message names the law's coefficients
        raise LinkURIError(f"{u.text!r}: coefficients={raw!r}: {err}") from None


def _sim_settings(u: LinkURI) -> dict:
    """The virtual robot's settings from a ``sim://`` URI, each checked as its option is.

    Called when the URI is parsed (the scheme's ``check``), so a bad value is refused before
    anything is opened or recorded: ``speed`` and ``seed`` at least 0 as ``--speed`` and
    ``--seed``, ``current`` from 0 to 1 m/s as ``--current`` (:data:`eelhost.wire.limits.MAX_CURRENT_M_S`).
    """
    speed = u.number("speed", 1.0)
    if speed < 0:
        raise LinkURIError(f"{u.text!r}: speed={speed:g} must be >= 0 (0 = as fast as possible)")
    seed = int(u.number("seed", 0, int))
    if seed < 0:
        raise LinkURIError(f"{u.text!r}: seed={seed} must be >= 0 (as --seed)")
    radio_name = u.one("radio", "xbee")
    if radio_name not in ("xbee", "ideal"):
        raise LinkURIError(f"{u.text!r}: radio={radio_name!r} (expected xbee or ideal)")
    loss = u.number("loss", 0.0)
    if not 0.0 <= loss <= 1.0:
        raise LinkURIError(f"{u.text!r}: loss={loss:g} must be in [0, 1]")
    drops = []
    for raw in u.params.get("drop", []):
        for window in raw.split(","):
            a, b = u.numbers("drop", window, 2)
            if not 0 <= a < b:
                raise LinkURIError(f"{u.text!r}: drop={window!r} needs 0 <= start < end")
            drops.append((a, b))
    start = u.one("start")
    x, y, heading = u.numbers("start", start, 3) if start else (0.0, 0.0, 0.0)
    current = u.one("current")
    c_speed, c_dir = u.numbers("current", current, 2) if current else (0.0, 0.0)
    if not 0 <= c_speed <= MAX_CURRENT_M_S:
        raise LinkURIError(f"{u.text!r}: current speed {c_speed:g} m/s must be from 0 to "
                           f"{MAX_CURRENT_M_S:g} m/s (as --current)")
    c = math.radians(c_dir)
    feedback = u.one("feedback", "0")
    if feedback not in ("0", "1"):
        raise LinkURIError(f"{u.text!r}: feedback={feedback!r} (expected 0 or 1)")
    battery = u.one("battery")
    battery_v = u.number("battery", 0.0) if battery is not None else None
    if battery_v is not None and not 0.0 < battery_v <= 30.0:
        raise LinkURIError(f"{u.text!r}: battery={battery_v:g} V must be in (0, 30]")
    coefficients = u.one("coefficients")
    if coefficients is not None and "=" not in coefficients:  # by name: checked by the law
        u.numbers("coefficients", coefficients, None)  # the law's own checks need the robot
    eeprom = u.one("eeprom")
    eeprom_path = Path(eeprom).expanduser() if eeprom else None
    if eeprom_path is not None and not eeprom_path.parent.is_dir():
        raise LinkURIError(f"{u.text!r}: eeprom={eeprom!r}: no directory {eeprom_path.parent}")
    if eeprom_path is not None and eeprom_path.exists() and eeprom_path.stat().st_size != 1024:
        raise LinkURIError(f"{u.text!r}: eeprom={eeprom!r} is not an EEPROM image of 1024 bytes")
    return {
        "start_position_m": (x, y),
        "start_heading_deg": heading,
        "current_m_s": (c_speed * math.cos(c), c_speed * math.sin(c)),
        "radio": (radio_name, loss),
        "drops_s": drops,
        "seed": seed,
        "speed": speed,
        "joint_feedback": feedback == "1",
        "battery_v": battery_v,
        "eeprom_path": eeprom_path,
    }


def _virtual_robot(u: LinkURI, robot: Robot) -> VirtualRobot:
    # Imported here: eelhost.xil builds on the link layer, and a URI can be parsed without
    # loading the native firmware.
    from eelhost.xil.radio import RadioModel
    from eelhost.xil.virtual_robot import VirtualRobot

    settings = _sim_settings(u)
    radio_name, loss = settings.pop("radio")
    radio = (RadioModel.xbee(loss_probability=loss) if radio_name == "xbee"
             else RadioModel(loss_probability=loss))
    return VirtualRobot(robot, radio=radio, **settings)


def _list_sim_ports() -> list[Port]:
    return [Port("sim://", "virtual robot: the native firmware driving the twin (always there)")]


register_transport(
    TransportScheme(
        name="sim",
        parameters=(
            "speed", "seed", "radio", "loss", "drop", "start", "current", "feedback", "battery",
            "coefficients", "eeprom",
        ),
        target="",
        open=_open_sim,
        list_ports=_list_sim_ports,
        example="sim://?speed=1&seed=0",
        check=_sim_settings,
        description="the virtual robot: the native firmware driving the twin",
    )
)
