"""What every message of the wire protocol shares: fields with a wire format, pack, unpack, check.

The generated :mod:`eelhost.wire.protocol` declares each message of ``protocol/eelbot.toml`` as a
frozen dataclass whose fields carry their wire format (:func:`wire_field`), derived from the schema;
the behaviour that does not depend on the schema is written here once (docs/firmware.md,
"Protocol").
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any, ClassVar, Self, TypeVar

_M = TypeVar("_M", bound="WireMessage")


def wire_field(
    struct_code: str,
    default: float = 0,
    *,
    count: int = 1,
    lo: float | None = None,
    hi: float | None = None,
) -> Any:
    """A message field: its default, with its wire format in the dataclass field's metadata.

    Parameters
    ----------
    struct_code : str
        The :mod:`struct` code of one value on the wire (the generated module maps the schema's
        u8, u16, i16, u32 and f32 to B, H, h, I and f).
    default : float
        The default (of every element when ``count > 1``).
    count : int
        Number of values; more than one makes the field a tuple.
    lo, hi : float, optional
        The range that :meth:`WireMessage.validate` enforces.
    """
    value = (default,) * count if count > 1 else default
    return field(default=value, metadata={"code": struct_code, "count": count, "range": (lo, hi)})


class WireMessage:
    """What every message shares: pack, unpack and validate, driven by its fields' metadata."""

    MSG_ID: ClassVar[int]
    TO_ROBOT: ClassVar[bool]
    FORMAT: ClassVar[str]
    PAYLOAD_BYTES: ClassVar[int]
    # (name, count, lo, hi) of each field in wire order, set by bind_message from the metadata.
    LAYOUT: ClassVar[tuple[tuple[str, int, float | None, float | None], ...]]

    if TYPE_CHECKING:

        def __init__(self, *values: Any) -> None: ...

    def pack(self) -> bytes:
        """Payload bytes of this message."""
        values: list[Any] = []
        for name, count, _, _ in self.LAYOUT:
            if count > 1:
                values.extend(getattr(self, name))
            else:
                values.append(getattr(self, name))
        return struct.pack(self.FORMAT, *values)

    @classmethod
    def unpack(cls, payload: bytes) -> Self:
        """Message from its payload bytes (struct.error on a wrong size)."""
        flat = struct.unpack(cls.FORMAT, payload)
        values: list[Any] = []
        for _, count, _, _ in cls.LAYOUT:
            values.append(tuple(flat[:count]) if count > 1 else flat[0])
            flat = flat[count:]
        return cls(*values)

    def validate(self) -> None:
        """Raise ValueError when a field is not finite or out of range."""
        for name, _, lo, hi in self.LAYOUT:
            v = getattr(self, name)
            if lo is not None and hi is not None and not (math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"{type(self).__name__}.{name}={v} outside [{lo}, {hi}]")


def bind_message(msg_id: int, *, to_robot: bool) -> Callable[[type[_M]], type[_M]]:
    """Class decorator: bind a message dataclass to its id and derive its wire format."""

    def bind(cls: type[_M]) -> type[_M]:
        wire = fields(cls)  # type: ignore[arg-type]
        cls.MSG_ID, cls.TO_ROBOT = msg_id, to_robot
        cls.LAYOUT = tuple((f.name, f.metadata["count"], *f.metadata["range"]) for f in wire)
        cls.FORMAT = "<" + "".join(
            (str(f.metadata["count"]) if f.metadata["count"] > 1 else "") + f.metadata["code"]
            for f in wire
        )
        cls.PAYLOAD_BYTES = struct.calcsize(cls.FORMAT)
        return cls

    return bind



@dataclass(frozen=True)
class SettingInfo:
    """One of the robot's settings (GetSetting, SetSetting): how the robot stores and checks it.

    Attributes
    ----------
    name : str
        Its name (``SETTINGS`` is keyed by it).
    key : int
        Its key on the wire (:class:`SettingKey`).
    wire_type : str
        How the robot stores it: u8, u16, i16 (whole values) or f32. Values travel as f32.
    count : int
        Elements: N_JOINTS for a per-joint setting (index 0 = joint 1), else 1.
    lo, hi : float
        The range the robot accepts.
    default : float
        The value a robot with a blank or corrupt EEPROM uses.
    doc : str
        What it means.
    """

    name: str
    key: int
    wire_type: str
    count: int
    lo: float
    hi: float
    default: float
    doc: str

    def check(self, value: float, index: int = 0) -> None:
        """Raise ValueError, naming the setting, when the robot would refuse this value or index."""
        if not 0 <= index < self.count:
            raise ValueError(f"{self.name}: index {index} outside 0..{self.count - 1}")
        if not (math.isfinite(value) and self.lo <= value <= self.hi):
            raise ValueError(f"{self.name}={value} outside [{self.lo}, {self.hi}]")
        if self.wire_type != "f32" and value != int(value):
            raise ValueError(f"{self.name}={value}: a whole number is needed")
