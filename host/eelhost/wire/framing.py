"""Framing of the wire protocol: CRC-16, COBS, and frames of header | payload | CRC.

Hand-written and shared by every message set: the generated ``eelhost.wire.protocol`` binds these
to its schema hash and message table (``encode_frame``, ``decode_frame``, ``FrameReader``). A frame
is ``COBS(schema_hash u16 | msg_id u8 | seq u8 | payload | [crc32 u32] | crc16 u16)`` followed by a
zero byte, little-endian, CRC-16/CCITT-FALSE over everything before it; messages to the robot
carry the CRC-32 (zlib's) of header and payload (docs/firmware.md, "Command integrity").
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable, Mapping
from typing import Any

HEADER_FORMAT = "<HBB"  # schema hash, message id, sequence number
HEADER_BYTES = struct.calcsize(HEADER_FORMAT)
CRC_BYTES = 2
COMMAND_CRC_BYTES = 4


class FrameError(ValueError):
    """A frame that must be dropped; ``kind`` names the counter it goes to.

    Kinds: ``cobs`` (garbage), ``short`` (truncated), ``oversize``, ``crc``, ``schema``,
    ``unknown_id``, ``length``, ``crc32`` (of a message to the robot).
    """

    def __init__(self, kind: str, detail: str) -> None:
        super().__init__(f"{kind}: {detail}")
        self.kind = kind


def crc16_ccitt_false(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor).

    Parameters
    ----------
    data : bytes
        The bytes to check.

    Returns
    -------
    int
        The CRC; ``crc16_ccitt_false(b"123456789") == 0x29B1``.
    """
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: the result contains no zero byte.

    Parameters
    ----------
    data : bytes
        Any bytes.

    Returns
    -------
    bytes
        The encoded bytes, without the zero delimiter.
    """
    out = bytearray()
    block = bytearray()
    for byte in data:
        if byte == 0:
            out.append(len(block) + 1)
            out += block
            block.clear()
        else:
            block.append(byte)
            if len(block) == 254:
                out.append(255)
                out += block
                block.clear()
    out.append(len(block) + 1)
    out += block
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Invert :func:`cobs_encode`.

    Parameters
    ----------
    data : bytes
        Encoded bytes without the delimiter.

    Returns
    -------
    bytes
        The decoded bytes.

    Raises
    ------
    FrameError
        With kind ``"cobs"`` when the input is not valid COBS.
    """
    out = bytearray()
    i = 0
    while i < len(data):
        code = data[i]
        end = i + code
        if code == 0 or end > len(data):
            raise FrameError("cobs", f"bad COBS code {code} at byte {i}")
        block = data[i + 1 : end]
        if 0 in block:
            raise FrameError("cobs", "zero byte inside a COBS block")
        out += block
        i = end
        if code != 255 and i < len(data):
            out.append(0)
    return bytes(out)


def encode(message: Any, seq: int, schema_hash: int) -> bytes:
    """Build the bytes to send for a message, zero delimiter included.

    Parameters
    ----------
    message : Message
        A generated message (has ``MSG_ID`` and ``pack()``).
    seq : int
        Sequence number, 0..255.
    schema_hash : int
        The protocol's schema hash.

    Returns
    -------
    bytes
        ``COBS(header | payload | crc)`` followed by the zero delimiter.
    """
    if not 0 <= seq <= 255:
        raise ValueError(f"seq must be in 0..255, got {seq}")
    body = struct.pack(HEADER_FORMAT, schema_hash, message.MSG_ID, seq) + message.pack()
    if message.TO_ROBOT:
        body += struct.pack("<I", zlib.crc32(body))
    body += struct.pack("<H", crc16_ccitt_false(body))
    return cobs_encode(body) + b"\x00"


def decode(
    encoded: bytes, schema_hash: int, messages: Mapping[int, type[Any]], max_frame_bytes: int
) -> tuple[int, Any]:
    """Decode one frame (the bytes between two zero delimiters).

    Parameters
    ----------
    encoded : bytes
        The COBS bytes, without the delimiter.
    schema_hash : int
        Frames of another schema are refused.
    messages : mapping
        Message id -> message class (with ``PAYLOAD_BYTES`` and ``unpack``).
    max_frame_bytes : int
        Largest frame on the wire, delimiter included.

    Returns
    -------
    seq : int
    message : Message

    Raises
    ------
    FrameError
        When the frame must be dropped (see its ``kind``).
    """
    if len(encoded) > max_frame_bytes - 1:
        raise FrameError("oversize", f"{len(encoded)} encoded bytes")
    body = cobs_decode(encoded)
    if len(body) < HEADER_BYTES + CRC_BYTES:
        raise FrameError("short", f"{len(body)} bytes")
    (crc,) = struct.unpack_from("<H", body, len(body) - CRC_BYTES)
    if crc != crc16_ccitt_false(body[:-CRC_BYTES]):
        raise FrameError("crc", "CRC mismatch")
    schema, msg_id, seq = struct.unpack_from(HEADER_FORMAT, body)
    if schema != schema_hash:
        raise FrameError("schema", f"peer schema 0x{schema:04X}, ours 0x{schema_hash:04X}")
    cls = messages.get(msg_id)
    if cls is None:
        raise FrameError("unknown_id", f"id 0x{msg_id:02X}")
    check = COMMAND_CRC_BYTES if cls.TO_ROBOT else 0
    if len(body) != HEADER_BYTES + cls.PAYLOAD_BYTES + check + CRC_BYTES:
        raise FrameError("length", f"{cls.__name__} needs {cls.PAYLOAD_BYTES} bytes")
    end = HEADER_BYTES + cls.PAYLOAD_BYTES
    if check and struct.unpack_from("<I", body, end)[0] != zlib.crc32(body[:end]):
        raise FrameError("crc32", "command CRC-32 mismatch")
    return seq, cls.unpack(body[HEADER_BYTES:end])


class StreamDecoder:
    """Split a byte stream at zero delimiters and decode the frames, counting the bad ones.

    Parameters
    ----------
    decode_frame : callable
        Decodes the bytes between two delimiters into ``(seq, message)`` or raises FrameError.
    """

    def __init__(self, decode_frame: Callable[[bytes], tuple[int, Any]]) -> None:
        self._decode = decode_frame
        self._buf = bytearray()
        self.bad: dict[str, int] = {}

    def feed(self, data: bytes) -> list[tuple[int, Any]]:
        """Consume received bytes.

        Parameters
        ----------
        data : bytes
            Bytes as they came from the link.

        Returns
        -------
        list of (seq, message)
            Frames completed by these bytes; bad frames are counted in ``bad`` and skipped.
        """
        out = []
        for byte in data:
            if byte != 0:
                self._buf.append(byte)
                continue
            if self._buf:
                try:
                    out.append(self._decode(bytes(self._buf)))
                except FrameError as err:
                    self.bad[err.kind] = self.bad.get(err.kind, 0) + 1
                self._buf.clear()
        return out
