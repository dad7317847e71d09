"""Render the eelbot protocol definition into a C++ header and a Python module.

Usage::

    python protocol/generate.py          # write the C++ header and the Python module
    python protocol/generate.py --check  # exit 1 when either differs from the definition

The definition is ``protocol/eelbot.toml``. The schema hash is the first two bytes of the SHA-256
of a canonical JSON form of everything that changes the meaning of bytes on the wire (ids, names,
types, counts, ranges, enum values, frame constants); documentation strings and defaults are left
out so that editing a doc does not break compatibility with robots already flashed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import textwrap
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFINITION = ROOT / "protocol" / "eelbot.toml"
CPP_OUT = ROOT / "firmware" / "core" / "protocol_gen.h"
PY_OUT = ROOT / "host" / "eelhost" / "wire" / "protocol.py"

# type name -> (size in bytes, struct code, C++ type)
TYPES = {
    "u8": (1, "B", "uint8_t"),
    "u16": (2, "H", "uint16_t"),
    "u32": (4, "I", "uint32_t"),
    "f32": (4, "f", "float"),
}
HEADER_BYTES = 4  # schema_hash u16, msg_id u8, seq u8 (frozen, see eelbot.toml)
CRC_BYTES = 2


class DefinitionError(ValueError):
    """The protocol definition is malformed."""


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

    @property
    def size(self) -> int:
        """Bytes on the wire."""
        return TYPES[self.type][0] * self.count


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
    def upper(self) -> str:
        """The name in UPPER_SNAKE case."""
        out = ""
        for i, ch in enumerate(self.name):
            if ch.isupper() and i:
                out += "_"
            out += ch.upper()
        return out


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


def load(path: Path | None = None) -> dict:
    """Read and validate the definition.

    Parameters
    ----------
    path : Path, optional
        The TOML definition (default ``protocol/eelbot.toml``).

    Returns
    -------
    dict
        With keys ``protocol``, ``frame``, ``enums`` (name -> list of (name, value, doc)),
        ``messages`` (list of Message) and ``schema_hash`` (int).

    Raises
    ------
    DefinitionError
        When a rule of the definition is broken (duplicate id, unknown type, frame too large...).
    """
    raw = tomllib.loads((path or DEFINITION).read_text(encoding="utf-8"))
    proto = raw["protocol"]
    frame = raw["frame"]
    want_frame = {
        "schema_hash": "u16",
        "msg_id": "u8",
        "seq": "u8",
        "crc": "crc16_ccitt_false",
        "delimiter": 0,
    }
    if frame != want_frame:
        raise DefinitionError(f"[frame] must be {want_frame} (the header is frozen), got {frame}")
    enums = {}
    for e in raw.get("enum", []):
        values = [(str(n), int(v), str(d)) for n, v, d in e["values"]]
        if len({v for _, v, _ in values}) != len(values):
            raise DefinitionError(f"enum {e['name']}: duplicate values")
        enums[e["name"]] = {"doc": e.get("doc", ""), "values": values}
    messages = []
    for m in raw["message"]:
        fields = []
        for f in m["fields"]:
            if f["type"] not in TYPES:
                raise DefinitionError(f"{m['name']}.{f['name']}: unknown type {f['type']!r}")
            if f.get("enum") and f["enum"] not in enums:
                raise DefinitionError(f"{m['name']}.{f['name']}: unknown enum {f['enum']!r}")
            fields.append(
                Field(
                    f["name"],
                    f["type"],
                    int(f.get("count", 1)),
                    f.get("doc", ""),
                    f.get("min"),
                    f.get("max"),
                    f.get("default"),
                    f.get("enum"),
                )
            )
        if len(m.get("doc", "")) > 88:
            raise DefinitionError(f"{m['name']}: doc longer than 88 characters (one line)")
        if m["direction"] not in ("to_robot", "to_host"):
            raise DefinitionError(f"{m['name']}: direction must be to_robot or to_host")
        messages.append(
            Message(m["name"], int(m["id"]), m["direction"], m.get("doc", ""), tuple(fields))
        )
    ids = [m.id for m in messages]
    if len(set(ids)) != len(ids) or not all(0 < i < 256 for i in ids):
        raise DefinitionError("message ids must be unique and in 1..255")
    for m in messages:
        size = cobs_worst_case(HEADER_BYTES + m.payload_bytes + CRC_BYTES) + 1
        if size > proto["max_frame_bytes"]:
            raise DefinitionError(f"{m.name}: {size} encoded bytes exceed max_frame_bytes")
    canonical = {
        "protocol": {
            k: proto[k] for k in ("name", "version", "baud", "max_frame_bytes", "n_joints")
        },
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
    }
    digest = hashlib.sha256(json.dumps(canonical, sort_keys=True).encode()).digest()
    return {
        "protocol": proto,
        "frame": frame,
        "enums": enums,
        "messages": messages,
        "schema_hash": int.from_bytes(digest[:2], "big"),
    }


def _camel(name: str) -> str:
    return "".join(p.capitalize() for p in name.lower().split("_"))


def _cpp_float(x: float) -> str:
    return f"{float(x)!r}f"


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
        "#include <stdint.h>",
        '#include "wire.h"',
        "",
        "namespace eelproto {",
        "",
        f"constexpr uint16_t kSchemaHash = 0x{d['schema_hash']:04X};",
        f"constexpr uint8_t kProtocolVersion = {p['version']};",
        f"constexpr uint32_t kBaud = {p['baud']}UL;",
        f"constexpr uint8_t kMaxFrameBytes = {p['max_frame_bytes']};  // encoded, with delimiter",
        f"constexpr uint8_t kHeaderBytes = {HEADER_BYTES};",
        f"constexpr uint8_t kCrcBytes = {CRC_BYTES};",
        f"constexpr uint8_t kJoints = {p['n_joints']};",
        "",
    ]
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
    for m in d["messages"]:
        out.append(f"// {m.doc} ({m.direction.replace('_', ' ')})")
        out.append(f"struct {m.name} {{")
        out.append(f"  static constexpr MsgId kId = MsgId::{m.name};")
        out.append(f"  static constexpr uint8_t kPayloadBytes = {m.payload_bytes};")
        for f in m.fields:
            ctype = TYPES[f.type][2]
            arr = f"[{f.count}]" if f.count > 1 else ""
            out.append(f"  {ctype} {f.name}{arr};  // {f.doc}")
        out += ["};", ""]
        var = "m" if m.fields else "/*m*/"
        pname = "p" if m.fields else ""
        out.append(f"inline void pack(const {m.name}& {var}, uint8_t* {pname}) {{")
        off = 0
        for f in m.fields:
            for k in range(f.count):
                idx = f"[{k}]" if f.count > 1 else ""
                out.append(f"  wire::put_{f.type}(p + {off}, m.{f.name}{idx});")
                off += TYPES[f.type][0]
        out.append("}")
        out.append(
            f"inline void unpack({m.name}& {var}, const uint8_t* {'p' if m.fields else ''}) {{"
        )
        off = 0
        for f in m.fields:
            for k in range(f.count):
                idx = f"[{k}]" if f.count > 1 else ""
                out.append(f"  m.{f.name}{idx} = wire::get_{f.type}(p + {off});")
                off += TYPES[f.type][0]
        out.append("}")
        ranged = [f for f in m.fields if f.min is not None or f.max is not None]
        if m.direction == "to_robot":
            out.append("// RefuseReason value, or 0 when every field is finite and in range.")
            out.append(f"inline uint8_t validate(const {m.name}& {'m' if ranged else '/*m*/'}) {{")
            for f in ranged:
                out.append(
                    f"  if (!wire::finite(m.{f.name})) return "
                    "static_cast<uint8_t>(RefuseReason::NotFinite);"
                )
            for f in ranged:
                conds = []
                if f.min is not None:
                    conds.append(f"m.{f.name} < {_cpp_float(f.min)}")
                if f.max is not None:
                    conds.append(f"m.{f.name} > {_cpp_float(f.max)}")
                out.append(
                    f"  if ({' || '.join(conds)}) return "
                    "static_cast<uint8_t>(RefuseReason::OutOfRange);"
                )
            out.append("  return 0;")
            out.append("}")
        defaults = [f for f in m.fields if f.default is not None]
        if defaults:
            out.append("// The documented defaults (also the firmware's boot values).")
            out.append(f"inline {m.name} default_{_snake(m.name)}() {{")
            out.append(f"  {m.name} m{{}};")
            for f in defaults:
                out.append(f"  m.{f.name} = {_cpp_float(f.default)};")
            out.append("  return m;")
            out.append("}")
        out.append("")
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
    out.append("}  // namespace eelproto")
    return "\n".join(out) + "\n"


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


def _py_default(f: Field) -> str:
    if f.count > 1:
        zero = "0.0" if f.type == "f32" else "0"
        return f"({', '.join([zero] * f.count)},)"
    if f.default is not None:
        return repr(float(f.default)) if f.type == "f32" else str(int(f.default))
    return "0.0" if f.type == "f32" else "0"


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
        "Frames are ``COBS(schema_hash:u16 | msg_id:u8 | seq:u8 | payload | crc16:u16) 0x00``,",
        "little-endian, CRC-16/CCITT-FALSE over header and payload.",
        '"""',
        "",
        "from __future__ import annotations",
        "",
        "import math",
        "import struct",
        "from dataclasses import dataclass, field",
        "from enum import IntEnum",
        "from typing import ClassVar",
        "",
        "from eelhost.wire import framing as _framing",
        "from eelhost.wire.framing import (  # noqa: F401 (part of this module's interface)",
        "    FrameError,",
        "    cobs_decode,",
        "    cobs_encode,",
        "    crc16_ccitt_false,",
        ")",
        "",
        f"SCHEMA_HASH = 0x{d['schema_hash']:04X}",
        f"PROTOCOL_VERSION = {p['version']}",
        f"BAUD = {p['baud']}",
        f"MAX_FRAME_BYTES = {p['max_frame_bytes']}",
        f"HEADER_BYTES = {HEADER_BYTES}",
        f"CRC_BYTES = {CRC_BYTES}",
        f"N_JOINTS = {p['n_joints']}",
        "",
    ]
    for name, e in d["enums"].items():
        out += ["", f"class {name}(IntEnum):", f'    """{e["doc"]}"""', ""]
        for n, v, doc in e["values"]:
            out += [f"    #: {line}" for line in textwrap.wrap(doc, 90)]
            out.append(f"    {n} = {v}")
        out.append("")
    out += ["", "class MsgId(IntEnum):", '    """Message ids."""', ""]
    for m in d["messages"]:
        out.append(f"    {m.upper} = 0x{m.id:02X}")
    out.append("")
    for m in d["messages"]:
        fmt = "<" + "".join(
            (str(f.count) if f.count > 1 else "") + TYPES[f.type][1] for f in m.fields
        )
        out += ["", "@dataclass(frozen=True)", f"class {m.name}:"]
        doc = textwrap.wrap(m.doc, 92)
        if not m.fields and len(doc) == 1:
            out.append(f'    """{doc[0]}"""')
        else:
            out.append(f'    """{doc[0]}')
            out += [f"    {line}" for line in doc[1:]]
        if m.fields:
            out += ["", "    Attributes", "    ----------"]
            for f in m.fields:
                kind = "float" if f.type == "f32" else "int"
                if f.count > 1:
                    kind = f"tuple of {f.count} {kind}"
                rng = ""
                if f.min is not None:
                    rng = f" Range [{f.min}, {f.max}]."
                out.append(f"    {f.name} : {kind}")
                out += [f"        {line}" for line in textwrap.wrap(f.doc + rng, 88)]
        if m.fields or len(doc) > 1:
            out.append('    """')
        out.append("")
        out.append(f"    MSG_ID: ClassVar[MsgId] = MsgId.{m.upper}")
        out.append(f"    PAYLOAD_BYTES: ClassVar[int] = {m.payload_bytes}")
        out.append(f'    FORMAT: ClassVar[str] = "{fmt}"')
        out.append(f"    TO_ROBOT: ClassVar[bool] = {m.direction == 'to_robot'}")
        for f in m.fields:
            pytype = "float" if f.type == "f32" else "int"
            if f.count > 1:
                out.append(f"    {f.name}: tuple[{pytype}, ...] = field(default={_py_default(f)})")
            else:
                out.append(f"    {f.name}: {pytype} = {_py_default(f)}")
        flat = []
        for f in m.fields:
            flat.append(f"*self.{f.name}" if f.count > 1 else f"self.{f.name}")
        out += ["", "    def pack(self) -> bytes:", '        """Payload bytes of this message."""']
        if m.fields:
            out.append("        return struct.pack(")
            out.append("            self.FORMAT,")
            out += [f"            {a}," for a in flat]
            out.append("        )")
        else:
            out.append('        return b""')
        out += [
            "",
            "    @classmethod",
            f"    def unpack(cls, payload: bytes) -> {m.name}:",
            '        """Message from its payload bytes (struct.error on a wrong size)."""',
        ]
        if m.fields:
            out.append("        v = struct.unpack(cls.FORMAT, payload)")
            args, i = [], 0
            for f in m.fields:
                if f.count > 1:
                    args.append(f"tuple(v[{i}:{i + f.count}])")
                else:
                    args.append(f"v[{i}]")
                i += f.count
            out.append("        return cls(")
            out += [f"            {a}," for a in args]
            out.append("        )")
        else:
            out.append("        struct.unpack(cls.FORMAT, payload)")
            out.append("        return cls()")
        ranged = [f for f in m.fields if f.min is not None or f.max is not None]
        out += [
            "",
            "    def validate(self) -> None:",
            '        """Raise ValueError when a field is not finite or out of range."""',
        ]
        if ranged:
            for f in ranged:
                out.append(f"        v = self.{f.name}")
                out.append(f"        if not math.isfinite(v) or not ({f.min!r} <= v <= {f.max!r}):")
                out.append(
                    f'            raise ValueError(f"{m.name}.{f.name}={{v}}'
                    f' outside [{f.min}, {f.max}]")'
                )
        else:
            out.append("        return None")
        out.append("")
    out += ["", "Message = " + " | ".join(m.name for m in d["messages"]), ""]
    out.append("MESSAGES: dict[int, type] = {")
    for m in d["messages"]:
        out.append(f"    MsgId.{m.upper}: {m.name},")
    out.append("}")
    return "\n".join(out) + PY_RUNTIME


def render_all() -> dict[Path, str]:
    """Render every output from the definition.

    Returns
    -------
    dict
        Output path -> text.
    """
    d = load()
    return {CPP_OUT: render_cpp(d), PY_OUT: render_python(d)}


def main(argv: list[str] | None = None) -> int:
    """Write the rendered files, or check them with ``--check``.

    Parameters
    ----------
    argv : list of str, optional
        Command line arguments.

    Returns
    -------
    int
        0 on success; 1 when ``--check`` finds a file that differs from the definition.
    """
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="fail when outputs are stale")
    args = ap.parse_args(argv)
    stale = []
    for path, text in render_all().items():
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
