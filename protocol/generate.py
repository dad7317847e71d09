"""Render the eelbot protocol definition into the firmware, the host and the docs.

Usage::

    python protocol/generate.py          # write every rendered file
    python protocol/generate.py --check  # exit 1 when any differs from the definition

The definition is ``protocol/eelbot.toml``. It renders into a C++ header (constants, message
structs and one field table per message, read by the generic codec of
``firmware/core/message_codec.h``; the settings struct and its table, read by
``firmware/core/settings_codec.h``), a Python module (one generic codec driven by each message's
field metadata, and the settings table), the twin's timing module ``sim/eelsim/firmware_timing.py``
(the constants marked ``twin = true``: the control period that is the twin's physics step, the
servo frame, the baud; the twin imports nothing of the host, so it gets its own copy), the same
constants as C macros for the simavr harness (``firmware/tools/timing_gen.h``), and three
places of hand-written files, spliced between marker comments: the ``EEL_JOINTS`` line of the
native library's C header, the tables of constants, messages and settings of ``docs/firmware.md``
and the serial monitor's baud in ``platformio.ini``.

The schema hash is the first two bytes of the SHA-256 of a canonical JSON form of everything that
changes the meaning of bytes on the wire (ids, names, types, counts, ranges, enum values, setting
keys, frame constants, baud, max_frame_bytes, n_joints); documentation strings, defaults and
periods are left out so that editing them does not break compatibility with robots already
flashed. The settings version, stored with the settings in the robot's EEPROM, is the same for the
settings' names, keys, types and counts: the layout of the stored bytes.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import sys
import textwrap
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFINITION = ROOT / "protocol" / "eelbot.toml"
CPP_OUT = ROOT / "firmware" / "core" / "protocol_gen.h"
PY_OUT = ROOT / "host" / "eelhost" / "wire" / "protocol.py"
SIM_TIMING_OUT = ROOT / "sim" / "eelsim" / "firmware_timing.py"
C_TIMING_OUT = ROOT / "firmware" / "tools" / "timing_gen.h"

# type name -> (size in bytes, struct code, C++ type)
TYPES = {
    "u8": (1, "B", "uint8_t"),
    "u16": (2, "H", "uint16_t"),
    "i16": (2, "h", "int16_t"),
    "u32": (4, "I", "uint32_t"),
    "f32": (4, "f", "float"),
}
# The whole range of each integer type (a setting's range must lie inside it).
INT_RANGES = {"u8": (0, 255), "u16": (0, 65535), "i16": (-32768, 32767), "u32": (0, 2**32 - 1)}
HEADER_BYTES = 4  # schema_hash u16, msg_id u8, seq u8 (frozen, see eelbot.toml)
CRC_BYTES = 2
COMMAND_CRC_BYTES = 4  # the CRC-32 of frames sent to the robot


NATIVE_H_OUT = ROOT / "firmware" / "hal" / "native" / "eel_native.h"
DOCS_OUT = ROOT / "docs" / "firmware.md"
PLATFORMIO_OUT = ROOT / "platformio.ini"

# The constants whose values enter the schema hash (with the messages, whose counts they may set).
WIRE_CONSTANTS = ("baud", "max_frame_bytes", "n_joints")
CONSTANT_TYPES = ("u8", "u16", "u32")


class DefinitionError(ValueError):
    """The protocol definition is malformed."""


class OutputError(ValueError):
    """A file that receives generated text has no marked place for it."""


@dataclass(frozen=True)
class Constant:
    """A number the firmware and the host share."""

    name: str
    value: int
    type: str
    doc: str
    twin: bool = False  # also rendered into the twin's timing module (SIM_TIMING_OUT)

    @property
    def cpp_name(self) -> str:
        """The C++ name, ``eelproto::k<CamelName>``."""
        return "k" + _camel(self.name)

    @property
    def py_name(self) -> str:
        """The Python name, upper case."""
        return self.name.upper()

    def quoted(self) -> str:
        """The value as a doc quotes it: a time in microseconds in s, ms or us."""
        if not self.name.endswith("_us"):
            return str(self.value)
        for unit, scale in (("s", 1_000_000), ("ms", 1000)):
            if self.value % scale == 0:
                return f"{self.value // scale} {unit}"
        return f"{self.value} us"


@dataclass(frozen=True)
class Field:
    """One field of a message."""

    name: str
    type: str
    count: int
    doc: str
    min: float | None
    max: float | None
    default: float | None
    enum: str | None
    count_name: str | None = None  # the constant that sets the count, if one does

    @property
    def size(self) -> int:
        """Bytes on the wire."""
        return TYPES[self.type][0] * self.count

    @property
    def ranged(self) -> bool:
        """Whether the receiver checks the value against [min, max] (and boots with the default)."""
        return self.min is not None


@dataclass(frozen=True)
class Message:
    """One message of the protocol."""

    name: str
    id: int
    direction: str
    doc: str
    fields: tuple[Field, ...]

    @property
    def payload_bytes(self) -> int:
        """Payload size in bytes."""
        return sum(f.size for f in self.fields)

    @property
    def check_bytes(self) -> int:
        """Bytes of the command CRC-32 in this message's frames (0 for messages to the host)."""
        return COMMAND_CRC_BYTES if self.direction == "to_robot" else 0

    @property
    def encoded_bytes(self) -> int:
        """Largest encoded frame of this message, zero delimiter included."""
        body = HEADER_BYTES + self.payload_bytes + self.check_bytes + CRC_BYTES
        return cobs_worst_case(body) + 1

    @property
    def upper(self) -> str:
        """The name in UPPER_SNAKE case."""
        out = ""
        for i, ch in enumerate(self.name):
            if ch.isupper() and i:
                out += "_"
            out += ch.upper()
        return out


@dataclass(frozen=True)
class Setting:
    """One of the robot's stored settings (a field of the settings struct, with its key)."""

    name: str
    key: int
    type: str
    count: int
    min: float
    max: float
    default: float
    doc: str
    count_name: str | None = None

    @property
    def size(self) -> int:
        """Bytes in the stored image."""
        return TYPES[self.type][0] * self.count

    @property
    def camel(self) -> str:
        """The key's C++ enumerator name."""
        return _camel(self.name)


def cobs_worst_case(n: int) -> int:
    """Return the worst-case COBS size of n bytes, without the delimiter.

    Parameters
    ----------
    n : int
        Unencoded size.

    Returns
    -------
    int
        n plus one overhead byte per started block of 254 bytes.
    """
    return n + 1 + n // 254


def _quote_constants(text: str, constants: dict[str, Constant], where: str) -> str:
    """Replace each {name} in a doc by the value of that constant."""

    def value(match: re.Match[str]) -> str:
        name = match.group(1)
        if name not in constants:
            raise DefinitionError(f"{where}: the doc quotes {{{name}}}, which is not a constant")
        return constants[name].quoted()

    return re.sub(r"\{(\w+)\}", value, text)


def _load_constants(raw: dict) -> dict[str, Constant]:
    """The [constants] tables, checked, with their docs' quotes of each other expanded."""
    consts = {}
    for name, c in raw.items():
        if not {"value", "type", "doc"} <= set(c) <= {"value", "type", "doc", "twin"}:
            raise DefinitionError(
                f"constants.{name}: needs exactly value, type and doc (and optionally twin)"
            )
        if not isinstance(c.get("twin", False), bool):
            raise DefinitionError(f"constants.{name}: twin must be true or false")
        if c["type"] not in CONSTANT_TYPES:
            raise DefinitionError(f"constants.{name}: type must be one of {CONSTANT_TYPES}")
        limit = 1 << (8 * TYPES[c["type"]][0])
        if not isinstance(c["value"], int) or not 0 <= c["value"] < limit:
            raise DefinitionError(f"constants.{name}: {c['value']!r} is not a {c['type']}")
        consts[name] = Constant(
            name, c["value"], c["type"], " ".join(c["doc"].split()), c.get("twin", False)
        )
    for name in WIRE_CONSTANTS:
        if name not in consts:
            raise DefinitionError(f"[constants] must define {name}")
    return {
        n: Constant(n, c.value, c.type, _quote_constants(c.doc, consts, f"constants.{n}"), c.twin)
        for n, c in consts.items()
    }


def _load_field(m: dict, f: dict, consts: dict[str, Constant], enums: dict) -> Field:
    """One field of message m, checked, its count resolved and its doc's quotes expanded."""
    where = f"{m['name']}.{f['name']}"
    if f["type"] not in TYPES:
        raise DefinitionError(f"{where}: unknown type {f['type']!r}")
    if f.get("enum") and f["enum"] not in enums:
        raise DefinitionError(f"{where}: unknown enum {f['enum']!r}")
    count, count_name = f.get("count", 1), None
    if isinstance(count, str):
        if count not in consts:
            raise DefinitionError(f"{where}: count names {count!r}, which is not a constant")
        count, count_name = consts[count].value, count
    if not isinstance(count, int) or count < 1:
        raise DefinitionError(f"{where}: count must be a positive integer or a constant's name")
    if len({"min" in f, "max" in f, "default" in f}) != 1:
        raise DefinitionError(f"{where}: give min, max and default together, or none of them")
    if "min" in f and (
        f["type"] != "f32" or count != 1 or not f["min"] <= f["default"] <= f["max"]
    ):
        raise DefinitionError(
            f"{where}: a range needs a single f32 field and min <= default <= max"
        )
    return Field(
        f["name"],
        f["type"],
        count,
        _quote_constants(f.get("doc", ""), consts, where),
        f.get("min"),
        f.get("max"),
        f.get("default"),
        f.get("enum"),
        count_name,
    )


def load(path: Path | None = None) -> dict:
    """Read and validate the definition.

    Parameters
    ----------
    path : Path, optional
        The TOML definition (default ``protocol/eelbot.toml``).

    Returns
    -------
    dict
        With keys ``protocol`` (name, version and the value of every constant), ``constants``
        (name -> Constant), ``frame``, ``enums`` (name -> doc and list of (name, value, doc)),
        ``messages`` (list of Message) and ``schema_hash`` (int).

    Raises
    ------
    DefinitionError
        When a rule of the definition is broken (duplicate id, unknown type or constant, frame too
        large...); the message names the table or field.
    """
    raw = tomllib.loads((path or DEFINITION).read_text(encoding="utf-8"))
    consts = _load_constants(raw.get("constants", {}))
    proto = {"name": raw["protocol"]["name"], "version": raw["protocol"]["version"]}
    proto |= {name: c.value for name, c in consts.items()}
    frame = raw["frame"]
    want_frame = {
        "schema_hash": "u16",
        "msg_id": "u8",
        "seq": "u8",
        "crc": "crc16_ccitt_false",
        "command_crc": "crc32_iso_hdlc",
        "delimiter": 0,
    }
    if frame != want_frame:
        raise DefinitionError(f"[frame] must be {want_frame} (the header is frozen), got {frame}")
    enums = {}
    for e in raw.get("enum", []):
        values = [
            (str(n), int(v), _quote_constants(str(d), consts, f"{e['name']}.{n}"))
            for n, v, d in e["values"]
        ]
        if len({v for _, v, _ in values}) != len(values):
            raise DefinitionError(f"enum {e['name']}: duplicate values")
        kind = e.get("kind", "values")
        if kind not in ("values", "flags"):
            raise DefinitionError(f"enum {e['name']}: kind must be values or flags")
        if kind == "flags" and any(v <= 0 or v & (v - 1) for _, v, _ in values):
            raise DefinitionError(f"enum {e['name']}: each flag must be one bit")
        enums[e["name"]] = {"doc": e.get("doc", ""), "values": values, "kind": kind}
    raw_messages = {m["name"]: m for m in raw["message"]}
    settings = _load_settings(raw.get("setting", []), raw_messages, consts)
    enums["SettingKey"] = {
        "doc": "Keys of the robot's settings (GetSetting, SetSetting, Setting).",
        "values": [(s.name.upper(), s.key, s.doc) for s in settings],
        "kind": "values",
    }
    messages = []
    for m in raw["message"]:
        fields = tuple(_load_field(m, f, consts, enums) for f in m["fields"])
        doc = _quote_constants(m.get("doc", ""), consts, m["name"])
        if len(doc) > 88:
            raise DefinitionError(f"{m['name']}: doc longer than 88 characters (one line)")
        if m["direction"] not in ("to_robot", "to_host"):
            raise DefinitionError(f"{m['name']}: direction must be to_robot or to_host")
        messages.append(Message(m["name"], int(m["id"]), m["direction"], doc, fields))
    ids = [m.id for m in messages]
    if len(set(ids)) != len(ids) or not all(0 < i < 256 for i in ids):
        raise DefinitionError("message ids must be unique and in 1..255")
    for m in messages:
        if m.encoded_bytes > proto["max_frame_bytes"]:
            raise DefinitionError(
                f"{m.name}: {m.encoded_bytes} encoded bytes exceed max_frame_bytes"
            )
    layout = [[s.name, s.key, s.type, s.count] for s in settings]
    canonical = {
        "protocol": {k: proto[k] for k in ("name", "version", *WIRE_CONSTANTS)},
        "frame": frame,
        "enums": {k: [(n, val) for n, val, _ in v["values"]] for k, v in enums.items()},
        "messages": [
            [
                m.name,
                m.id,
                m.direction,
                [[f.name, f.type, f.count, f.min, f.max, f.enum] for f in m.fields],
            ]
            for m in messages
        ],
        "settings": [[*row, s.min, s.max] for row, s in zip(layout, settings, strict=True)],
    }
    return {
        "protocol": proto,
        "constants": consts,
        "frame": frame,
        "enums": enums,
        "messages": messages,
        "settings": settings,
        "schema_hash": _hash16(canonical),
        "settings_version": _hash16(layout),
    }


def _hash16(canonical: object) -> int:
    """The first two bytes of the SHA-256 of a canonical JSON form."""
    digest = hashlib.sha256(json.dumps(canonical, sort_keys=True).encode()).digest()
    return int.from_bytes(digest[:2], "big")


def _load_settings(raw: list, messages: dict, consts: dict[str, Constant]) -> list[Setting]:
    """The [[setting]] tables, checked, those with ``from`` completed from the command field."""
    settings = []
    for s in raw:
        where = f"setting {s.get('name', s.get('from', '?'))}"
        s = dict(s)
        if "from" in s:
            msg_name, _, field_name = s.pop("from").partition(".")
            fields = {f["name"]: f for f in messages.get(msg_name, {}).get("fields", [])}
            if field_name not in fields or "min" not in fields[field_name]:
                raise DefinitionError(f"{where}: from names no ranged field of a message")
            f = fields[field_name]
            s = {k: f[k] for k in ("name", "type", "min", "max", "default", "doc")} | s
        need = {"name", "key", "type", "min", "max", "default", "doc"}
        if not need <= set(s) <= need | {"count"}:
            raise DefinitionError(f"{where}: needs name, key, type, min, max, default and doc")
        if s["type"] not in TYPES or s["type"] == "u32":
            raise DefinitionError(f"{where}: type must be u8, u16, i16 or f32")
        count, count_name = s.get("count", 1), None
        if isinstance(count, str):
            if count not in consts:
                raise DefinitionError(f"{where}: count names {count!r}, which is not a constant")
            count, count_name = consts[count].value, count
        lo, hi, default = s["min"], s["max"], s["default"]
        if not lo <= default <= hi:
            raise DefinitionError(f"{where}: needs min <= default <= max")
        if s["type"] != "f32":
            tlo, thi = INT_RANGES[s["type"]]
            if not all(isinstance(v, int) for v in (lo, hi, default)) or lo < tlo or hi > thi:
                raise DefinitionError(f"{where}: an integer setting needs whole bounds in its type")
        if not 0 < s["key"] < 256:
            raise DefinitionError(f"{where}: key must be in 1..255")
        doc = _quote_constants(" ".join(s["doc"].split()), consts, where)
        settings.append(
            Setting(s["name"], s["key"], s["type"], count, lo, hi, default, doc, count_name)
        )
    if len({s.key for s in settings}) != len(settings):
        raise DefinitionError("setting keys must be unique")
    if len({s.name for s in settings}) != len(settings):
        raise DefinitionError("setting names must be unique")
    return settings


def _camel(name: str) -> str:
    return "".join(p.capitalize() for p in name.lower().split("_"))


def _cpp_float(x: float) -> str:
    return f"{float(x)!r}f"


def _comment(prefix: str, text: str, width: int = 100) -> list[str]:
    """Text as comment lines of at most width characters."""
    return textwrap.wrap(text, width, initial_indent=prefix, subsequent_indent=prefix)


def render_cpp(d: dict) -> str:
    """Render the C++ header.

    Parameters
    ----------
    d : dict
        The loaded definition (see :func:`load`).

    Returns
    -------
    str
        The text of ``firmware/core/protocol_gen.h``.
    """
    p = d["protocol"]
    out = [
        "// GENERATED by protocol/generate.py from protocol/eelbot.toml. Do not edit: edit the",
        "// definition and run `python protocol/generate.py`.",
        "#pragma once",
        "#include <stddef.h>",
        "#include <stdint.h>",
        "",
        '#include "flash_table.h"',
        "",
        "namespace eelproto {",
        "",
        f"constexpr uint16_t kSchemaHash = 0x{d['schema_hash']:04X};",
        f"constexpr uint8_t kProtocolVersion = {p['version']};",
        f"constexpr uint8_t kHeaderBytes = {HEADER_BYTES};",
        f"constexpr uint8_t kCrcBytes = {CRC_BYTES};",
        "// Bytes of the CRC-32 that frames sent to the robot carry before their CRC-16.",
        f"constexpr uint8_t kCommandCrcBytes = {COMMAND_CRC_BYTES};",
        f"constexpr uint16_t kSettingsVersion = 0x{d['settings_version']:04X};",
        "",
    ]
    for c in d["constants"].values():
        suffix = "UL" if c.type == "u32" else ""
        out += _comment("// ", c.doc)
        out.append(f"constexpr {TYPES[c.type][2]} {c.cpp_name} = {c.value}{suffix};")
    out.append("")
    for name, e in d["enums"].items():
        out.append(f"// {e['doc']}")
        out.append(f"enum class {name} : uint8_t {{")
        for n, v, doc in e["values"]:
            out.append(f"  {_camel(n)} = {v},  // {doc}")
        out += ["};", ""]
    out.append("enum class MsgId : uint8_t {")
    for m in d["messages"]:
        out.append(f"  {m.name} = 0x{m.id:02X},")
    out += ["};", ""]
    out += [
        "// Each message's field table is its each_field(): visit(field, wire offset) for each",
        "// field in wire order, visit(field, wire offset, min, max, default) for a command's field",
        "// (see message_codec.h).",
        "",
    ]
    for m in d["messages"]:
        out += _cpp_message(d, m)
    out.append("// Payload size of a message id, or -1 for an id this schema does not define.")
    out.append("inline int16_t payload_bytes(uint8_t id) {")
    out.append("  switch (id) {")
    for m in d["messages"]:
        out.append(f"    case 0x{m.id:02X}: return {m.payload_bytes};")
    out += ["    default: return -1;", "  }", "}", ""]
    out.append("// Messages the robot accepts (the others it only sends).")
    out.append("inline bool is_to_robot(uint8_t id) {")
    out.append("  switch (id) {")
    for m in d["messages"]:
        if m.direction == "to_robot":
            out.append(f"    case 0x{m.id:02X}:")
    out += ["      return true;", "    default:", "      return false;", "  }", "}", ""]
    out += _cpp_settings(d)
    out.append("}  // namespace eelproto")
    return "\n".join(out) + "\n"


SETTING_TYPES = {"u8": "U8", "u16": "U16", "i16": "I16", "f32": "F32"}


def _cpp_settings(d: dict) -> list[str]:
    """The settings struct and the settings table (read by settings_codec.cpp)."""
    settings = d["settings"]
    out = [
        "// The robot's settings (the settings table of docs/firmware.md).",
        "struct Settings {",
    ]
    for s in settings:
        arr = (
            f"[{d['constants'][s.count_name].cpp_name}]"
            if s.count_name
            else (f"[{s.count}]" if s.count > 1 else "")
        )
        out += _comment("  // ", s.doc)
        out.append(f"  {TYPES[s.type][2]} {s.name}{arr};")
    out += [
        "};",
        "",
        "enum class SettingType : uint8_t { U8, U16, I16, F32 };",
        "",
        "// One row of the settings table: how a setting is stored and checked.",
        "struct SettingInfo {",
        "  uint8_t key;",
        "  SettingType type;",
        "  uint8_t count;   // elements (per joint: kNJoints)",
        "  uint8_t offset;  // of element 0 in struct Settings",
        "  float min, max, default_value;",
        "};",
        "",
        f"constexpr uint8_t kSettingCount = {len(settings)};",
        "// Bytes of the settings in the EEPROM image: each row's elements, little-endian, in order.",
        f"constexpr uint8_t kSettingsBytes = {sum(s.size for s in settings)};",
        "// In program memory on the AVR (flash_table.h): read rows with flash_read().",
        "EEL_FLASH_TABLE constexpr SettingInfo kSettingTable[kSettingCount] = {",
    ]
    for s in settings:
        count = d["constants"][s.count_name].cpp_name if s.count_name else str(s.count)
        bounds = ", ".join(_cpp_float(x) for x in (s.min, s.max, s.default))
        out.append(
            f"    {{{s.key}, SettingType::{SETTING_TYPES[s.type]}, {count}, "
            f"offsetof(Settings, {s.name}), {bounds}}},"
        )
    out += ["};", ""]
    return out


def _cpp_message(d: dict, m: Message) -> list[str]:
    """The struct, field table and defaults of one message."""
    out = [
        f"// {m.doc} ({m.direction.replace('_', ' ')})",
        f"struct {m.name} {{",
        f"  static constexpr MsgId kId = MsgId::{m.name};",
        f"  static constexpr uint8_t kPayloadBytes = {m.payload_bytes};",
    ]
    for f in m.fields:
        size = d["constants"][f.count_name].cpp_name if f.count_name else f.count
        arr = f"[{size}]" if f.count > 1 else ""
        out.append(f"  {TYPES[f.type][2]} {f.name}{arr};  // {f.doc}")
    out.append("};")
    if not m.fields:
        out += [f"template <typename Visit> void each_field({m.name}&, Visit&) {{}}", ""]
        return out
    out += ["template <typename Visit>", f"void each_field({m.name}& m, Visit& visit) {{"]
    offset = 0
    for f in m.fields:
        args = [f"m.{f.name}", str(offset)]
        if f.ranged:
            args += [_cpp_float(f.min), _cpp_float(f.max), _cpp_float(f.default)]
        out.append(f"  visit({', '.join(args)});")
        offset += f.size
    out += ["}", ""]
    return out


def _snake(name: str) -> str:
    return Message(name, 0, "to_host", "", ()).upper.lower()


PY_RUNTIME = '''

# The framing is hand-written once in eelhost.wire.framing; these bind it to this schema.


def encode_frame(message: Message, seq: int) -> bytes:
    """Build the bytes to send for a message (see :func:`eelhost.wire.framing.encode`)."""
    return _framing.encode(message, seq, SCHEMA_HASH)


def decode_frame(encoded: bytes) -> tuple[int, Message]:
    """Decode the bytes between two zero delimiters (see :func:`eelhost.wire.framing.decode`)."""
    return _framing.decode(encoded, SCHEMA_HASH, MESSAGES, MAX_FRAME_BYTES)


class FrameReader(_framing.StreamDecoder):
    """Split a byte stream at zero delimiters and decode this schema's frames, counting bad ones."""

    def __init__(self) -> None:
        super().__init__(decode_frame)
'''


# Emitted once into the Python module, after MsgId: what every message shares.
PY_MESSAGE_BASE = '''

_STRUCT_CODES = {STRUCT_CODES}


def _wire(wire_type: str, default: float = 0, **layout: Any) -> Any:
    """A field of this schema's ``wire_type`` (:func:`eelhost.wire.messages.wire_field`)."""
    return wire_field(_STRUCT_CODES[wire_type], default, **layout)
'''


# Emitted once into the Python module, before the settings table.
PY_SETTINGS_BASE = '''

'''


def _py_count(d: dict, f: Field) -> str:
    """A field's count as the Python module spells it: the constant's name, if one sets it."""
    return d["constants"][f.count_name].py_name if f.count_name else str(f.count)


def _py_message(d: dict, m: Message) -> list[str]:
    """The dataclass of one message: its docstring and one line per field."""
    to_robot = m.direction == "to_robot"
    out = ["", "", f"@bind_message(MsgId.{m.upper}, to_robot={to_robot})", "@dataclass(frozen=True)"]
    out.append(f"class {m.name}(WireMessage):")
    doc = textwrap.wrap(m.doc, 92)
    if not m.fields and len(doc) == 1:
        return out + [f'    """{doc[0]}"""']
    out.append(f'    """{doc[0]}')
    out += [f"    {line}" for line in doc[1:]]
    if m.fields:
        out += ["", "    Attributes", "    ----------"]
        for f in m.fields:
            kind = "float" if f.type == "f32" else "int"
            if f.count > 1:
                kind = f"tuple of {_py_count(d, f)} {kind}"
            rng = f" Range [{f.min}, {f.max}]." if f.ranged else ""
            out.append(f"    {f.name} : {kind}")
            out += [f"        {line}" for line in textwrap.wrap(f.doc + rng, 88)]
    out += ['    """', ""]
    for f in m.fields:
        pytype = "float" if f.type == "f32" else "int"
        args = [f'"{f.type}"']
        if f.default is not None or f.type == "f32":
            value = f.default or 0
            args.append(repr(float(value)) if f.type == "f32" else str(int(value)))
        if f.count > 1:
            pytype = f"tuple[{pytype}, ...]"
            args.append(f"count={_py_count(d, f)}")
        if f.ranged:
            args += [f"lo={f.min!r}", f"hi={f.max!r}"]
        out.append(f"    {f.name}: {pytype} = _wire({', '.join(args)})")
    return out


def render_python(d: dict) -> str:
    """Render the Python module.

    Parameters
    ----------
    d : dict
        The loaded definition (see :func:`load`).

    Returns
    -------
    str
        The text of ``host/eelhost/wire/protocol.py``.
    """
    p = d["protocol"]
    out = [
        '"""The eelbot wire protocol, GENERATED by protocol/generate.py: do not edit.',
        "",
        "Edit ``protocol/eelbot.toml`` and run ``python protocol/generate.py``.",
        "Frames are ``COBS(schema_hash:u16 | msg_id:u8 | seq:u8 | payload | [crc32:u32] |",
        "crc16:u16) 0x00``, little-endian, CRC-16/CCITT-FALSE over everything before it; frames",
        "sent to the robot carry the CRC-32 (ISO-HDLC, as zlib.crc32) of header and payload.",
        '"""',
        "",
        "from __future__ import annotations",
        "",
        "from dataclasses import dataclass",
        "from enum import IntEnum, IntFlag",
        "from typing import Any",
        "",
        "from eelhost.wire import framing as _framing",
        "from eelhost.wire.framing import (  # noqa: F401 (part of this module's interface)",
        "    FrameError,",
        "    cobs_decode,",
        "    cobs_encode,",
        "    crc16_ccitt_false,",
        ")",
        "from eelhost.wire.messages import SettingInfo, WireMessage, bind_message, wire_field",
        "",
        f"SCHEMA_HASH = 0x{d['schema_hash']:04X}",
        f"PROTOCOL_VERSION = {p['version']}",
        f"HEADER_BYTES = {HEADER_BYTES}",
        f"CRC_BYTES = {CRC_BYTES}",
        f"COMMAND_CRC_BYTES = {COMMAND_CRC_BYTES}",
        f"SETTINGS_VERSION = 0x{d['settings_version']:04X}",
    ]
    for c in d["constants"].values():
        out += _comment("#: ", c.doc)
        out.append(f"{c.py_name} = {c.value}")
    out.append("")
    for name, e in d["enums"].items():
        base = "IntFlag" if e["kind"] == "flags" else "IntEnum"
        out += ["", f"class {name}({base}):", f'    """{e["doc"]}"""', ""]
        for n, v, doc in e["values"]:
            out += [f"    #: {line}" for line in textwrap.wrap(doc, 90)]
            out.append(f"    {n} = {v}")
        out.append("")
    out += ["", "class MsgId(IntEnum):", '    """Message ids."""', ""]
    for m in d["messages"]:
        out.append(f"    {m.upper} = 0x{m.id:02X}")
    codes = {name: code for name, (_, code, _) in TYPES.items()}
    out.append(PY_MESSAGE_BASE.replace("{STRUCT_CODES}", json.dumps(codes)).rstrip("\n"))
    for m in d["messages"]:
        out += _py_message(d, m)
    out += ["", "", "Message = " + " | ".join(m.name for m in d["messages"]), ""]
    out.append("MESSAGES: dict[int, type] = {")
    for m in d["messages"]:
        out.append(f"    MsgId.{m.upper}: {m.name},")
    out.append("}")
    out.append(PY_SETTINGS_BASE.rstrip("\n"))
    out.append("SETTINGS: dict[str, SettingInfo] = {")
    for s in d["settings"]:
        count = d["constants"][s.count_name].py_name if s.count_name else str(s.count)
        args = f'"{s.name}", {s.key}, "{s.type}", {count}, {s.min!r}, {s.max!r}, {s.default!r}'
        out.append(f'    "{s.name}": SettingInfo(')
        out.append(f"        {args},")
        doc = textwrap.wrap(s.doc, 84)
        out += [
            f"        {json.dumps(line + (' ' if k < len(doc) - 1 else ''))}"
            for k, line in enumerate(doc)
        ]
        out.append("    ),")
    out.append("}")
    return "\n".join(out) + PY_RUNTIME


def render_sim_timing(d: dict) -> str:
    """Render the twin's timing module: the constants marked ``twin = true``.

    Parameters
    ----------
    d : dict
        The loaded definition (see :func:`load`).

    Returns
    -------
    str
        The text of ``sim/eelsim/firmware_timing.py``.
    """
    out = [
        '"""The robot\'s timing as the twin needs it, GENERATED by protocol/generate.py: do not edit.',
        "",
        "Edit ``protocol/eelbot.toml`` (the constants marked ``twin = true``) and run",
        "``python protocol/generate.py``. The same numbers are ``eelproto::k<Name>`` in the firmware",
        "(``firmware/core/protocol_gen.h``) and ``eelhost.wire.protocol.<NAME>`` on the host; the twin",
        "imports nothing of the host, so it has this copy. :mod:`eelsim.timing` derives the physics",
        "step from ``CONTROL_PERIOD_US`` (docs/firmware.md, \"Timing defined once\").",
        '"""',
        "",
        "from __future__ import annotations",
        "",
        "__all__ = [" + ", ".join(f'"{c.py_name}"' for c in d["constants"].values() if c.twin) + "]",
    ]
    for c in d["constants"].values():
        if c.twin:
            out += ["", *_comment("#: ", c.doc), f"{c.py_name} = {c.value}"]
    return "\n".join(out) + "\n"


def render_c_timing(d: dict) -> str:
    """Render the C header of the same timing constants, for the simavr harness (plain C).

    Parameters
    ----------
    d : dict
        The loaded definition (see :func:`load`).

    Returns
    -------
    str
        The text of ``firmware/tools/timing_gen.h``: one ``#define EEL_<NAME>`` per constant
        marked ``twin = true``.
    """
    out = [
        "/* GENERATED by protocol/generate.py from protocol/eelbot.toml. Do not edit: edit the",
        " * definition and run `python protocol/generate.py`. The timing constants marked twin = true",
        " * as C macros, for the simavr harness (tools/eel_avrsim.c, C): the firmware's C++ has them",
        " * as eelproto::k<Name> (core/protocol_gen.h), the twin as eelsim.firmware_timing. */",
        "#ifndef EEL_TIMING_GEN_H",
        "#define EEL_TIMING_GEN_H",
    ]
    for c in d["constants"].values():
        if c.twin:
            out += ["", *_comment_block(c.doc), f"#define EEL_{c.py_name} {c.value}UL"]
    out += ["", "#endif"]
    return "\n".join(out) + "\n"


def _comment_block(text: str) -> list[str]:
    """Text as a C block comment of lines of at most 100 characters."""
    lines = textwrap.wrap(text, 96)
    lines[0] = "/* " + lines[0]
    lines[1:] = [" * " + line for line in lines[1:]]
    lines[-1] += " */"
    return lines


def _number(x: float) -> str:
    return f"{x:g}"


def _docs_constants(d: dict) -> str:
    """The Markdown table of the shared constants, one row per constant."""
    out = [
        "| constant | value | firmware (C++) | host (Python) | twin (Python) | meaning |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for c in d["constants"].values():
        twin = f"`{c.py_name}`" if c.twin else ""
        out.append(
            f"| `{c.name}` | {c.value} | `eelproto::{c.cpp_name}` | `{c.py_name}` | {twin} "
            f"| {c.doc} |"
        )
    return "\n".join(out) + "\n"


def _docs_field(d: dict, f: Field) -> str:
    """One field as the message table shows it: name, type, count, range, default, enum."""
    text = f"{f.name} {f.type}"
    if f.count > 1:
        text += f" x {f.count_name} ({f.count})" if f.count_name else f" x {f.count}"
    if f.ranged:
        text += f" [{_number(f.min)}, {_number(f.max)}]"
    if f.default is not None:
        text += f" ({_number(f.default)})"
    if f.enum == "SettingKey":
        text += " (a key of the settings table)"
    elif f.enum:
        values = d["enums"][f.enum]["values"]
        text += " (" + ", ".join(f"{n} {v}" for n, v, _ in values) + ")"
    return text


def _docs_messages(d: dict) -> str:
    """The schema hash and the Markdown table of messages, one row per message."""
    out = [
        f"Schema hash of this definition: **0x{d['schema_hash']:04X}**.",
        "",
        "| id | name | direction | payload (bytes) | encoded frame (bytes, at most) | fields "
        "| what |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for m in d["messages"]:
        fields = ", ".join(_docs_field(d, f) for f in m.fields) or "(none)"
        out.append(
            f"| 0x{m.id:02X} | {m.name} | {m.direction.replace('_', ' ')} | {m.payload_bytes} "
            f"| {m.encoded_bytes} | {fields} | {m.doc} |"
        )
    return "\n".join(out) + "\n"


def _docs_settings(d: dict) -> str:
    """The settings version and the Markdown table of settings, one row per setting."""
    out = [
        f"Settings version of this definition: **0x{d['settings_version']:04X}**.",
        "",
        "| key | name | stored as | range | default | meaning |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for s in d["settings"]:
        kind = s.type + (f" x {s.count_name} ({s.count})" if s.count_name else "")
        out.append(
            f"| {s.key} | `{s.name}` | {kind} | [{_number(s.min)}, {_number(s.max)}] "
            f"| {_number(s.default)} | {s.doc.replace('|', chr(92) + '|')} |"
        )
    return "\n".join(out) + "\n"


def _native_joints(d: dict) -> str:
    """The ``#define EEL_JOINTS`` line (a plain number: the host's cffi binding reads it)."""
    return f"#define EEL_JOINTS {d['constants']['n_joints'].value}\n"


def splice(text: str, region: str, body: str, comment: tuple[str, str], path: Path) -> str:
    """Put body between the BEGIN and END marker lines of a region of a hand-written file.

    Parameters
    ----------
    text : str
        The file's text.
    region : str
        The region's name, as the markers spell it.
    body : str
        The generated text (ending in a newline).
    comment : tuple of str
        How the file's language opens and closes a comment (``("<!--", "-->")``, ``(";", "")``).
    path : Path
        The file, for the error message.

    Returns
    -------
    str
        The text with the region's old body replaced.

    Raises
    ------
    OutputError
        When the file lacks either marker, or has them in the wrong order.
    """
    opening, closing = comment
    begin = f"{opening} BEGIN GENERATED by protocol/generate.py: {region} {closing}".rstrip() + "\n"
    end = f"{opening} END GENERATED: {region} {closing}".rstrip() + "\n"
    start, stop = text.find(begin), text.find(end)
    if start < 0 or stop < start:
        raise OutputError(
            f"{path}: needs the lines {begin.strip()!r} and then {end.strip()!r} "
            "around the generated text"
        )
    return text[: start + len(begin)] + body + text[stop:]


def render_all() -> dict[Path, str]:
    """Render every output from the definition.

    Returns
    -------
    dict
        Output path -> its whole text as it should be (spliced files: as they are, with their
        generated regions rendered).
    """
    d = load()
    docs = DOCS_OUT.read_text(encoding="utf-8")
    docs = splice(docs, "constants", _docs_constants(d), ("<!--", "-->"), DOCS_OUT)
    docs = splice(docs, "messages", _docs_messages(d), ("<!--", "-->"), DOCS_OUT)
    docs = splice(docs, "settings", _docs_settings(d), ("<!--", "-->"), DOCS_OUT)
    native = NATIVE_H_OUT.read_text(encoding="utf-8")
    native = splice(native, "joints", _native_joints(d), ("/*", "*/"), NATIVE_H_OUT)
    pio = PLATFORMIO_OUT.read_text(encoding="utf-8")
    monitor = f"monitor_speed = {d['constants']['baud'].value}\n"
    pio = splice(pio, "baud", monitor, (";", ""), PLATFORMIO_OUT)
    return {
        CPP_OUT: render_cpp(d),
        PY_OUT: render_python(d),
        SIM_TIMING_OUT: render_sim_timing(d),
        C_TIMING_OUT: render_c_timing(d),
        NATIVE_H_OUT: native,
        DOCS_OUT: docs,
        PLATFORMIO_OUT: pio,
    }


def main(argv: list[str] | None = None) -> int:
    """Write the rendered files, or check them with ``--check``.

    Parameters
    ----------
    argv : list of str, optional
        Command line arguments.

    Returns
    -------
    int
        0 on success; 1 when ``--check`` finds a file that differs from the definition, or when
        the definition is malformed or a file lacks its markers (the error is printed).
    """
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="fail when outputs are stale")
    args = ap.parse_args(argv)
    try:
        rendered = render_all()
    except (DefinitionError, OutputError) as err:
        print(f"protocol/generate.py: {err}", file=sys.stderr)
        return 1
    stale = []
    for path, text in rendered.items():
        current = path.read_text(encoding="utf-8") if path.exists() else None
        if current != text:
            if args.check:
                stale.append(path)
            else:
                path.write_text(text, encoding="utf-8")
                print(f"wrote {path.relative_to(ROOT)}")
    if stale:
        for path in stale:
            print(
                f"{path.relative_to(ROOT)} differs from protocol/eelbot.toml; "
                "run: python protocol/generate.py",
                file=sys.stderr,
            )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
