"""The protocol definition, its generator's check, and the generated Python codec."""

import importlib.util
import math
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from eelhost.wire import protocol as p

ROOT = Path(__file__).resolve().parents[2]


def load_generator():
    spec = importlib.util.spec_from_file_location("eel_generate", ROOT / "protocol" / "generate.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def test_rendered_files_match_the_definition():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "protocol" / "generate.py"), "--check"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr


def test_check_fails_when_a_rendered_file_drifts(tmp_path, monkeypatch, capsys):
    gen = load_generator()
    stale_cpp = tmp_path / "protocol_gen.h"
    stale_py = tmp_path / "protocol.py"
    stale_cpp.write_text(gen.CPP_OUT.read_text().replace("kBaud = 57600UL", "kBaud = 9600UL"))
    stale_py.write_text(gen.PY_OUT.read_text())
    monkeypatch.setattr(gen, "CPP_OUT", stale_cpp)
    monkeypatch.setattr(gen, "PY_OUT", stale_py)
    monkeypatch.setattr(gen, "ROOT", tmp_path)
    assert gen.main(["--check"]) == 1
    assert "protocol_gen.h differs" in capsys.readouterr().err
    assert stale_py.read_text() == gen.PY_OUT.read_text()  # check mode writes nothing


def test_schema_hash_follows_wire_changes_but_not_doc_changes(tmp_path):
    gen = load_generator()
    text = (ROOT / "protocol" / "eelbot.toml").read_text()
    base = gen.load()["schema_hash"]
    assert base == p.SCHEMA_HASH
    doc_edit = tmp_path / "doc.toml"
    doc_edit.write_text(text.replace('doc = "Why."', 'doc = "The reason."'))
    assert gen.load(doc_edit)["schema_hash"] == base
    type_edit = tmp_path / "type.toml"
    type_edit.write_text(
        text.replace('name = "frames_lost", type = "u16"', 'name = "frames_lost", type = "u32"')
    )
    assert gen.load(type_edit)["schema_hash"] != base


def test_definition_errors_are_reported_clearly(tmp_path):
    gen = load_generator()
    text = (ROOT / "protocol" / "eelbot.toml").read_text()
    dup = tmp_path / "dup.toml"
    dup.write_text(text.replace("id = 0x05", "id = 0x04"))
    with pytest.raises(gen.DefinitionError, match="unique"):
        gen.load(dup)
    big = tmp_path / "big.toml"
    big.write_text(text.replace('type = "f32", count = 5', 'type = "f32", count = 15'))
    with pytest.raises(gen.DefinitionError, match="exceed max_frame_bytes"):
        gen.load(big)


def test_crc16_matches_the_published_check_value():
    assert p.crc16_ccitt_false(b"123456789") == 0x29B1


@pytest.mark.parametrize(
    "data",
    [b"", b"\x00", b"\x00\x00", b"\x11\x22\x00\x33", bytes(range(256)) * 2, b"\x01" * 254],
)
def test_cobs_round_trips_and_removes_zeros(data):
    enc = p.cobs_encode(data)
    assert 0 not in enc
    assert p.cobs_decode(enc) == data


# Values exact in float32, so that a round trip through the f32 wire format is exact.
ALL_MESSAGES = [
    p.Hello(),
    p.SetGait(amplitude_rad=0.75, omega_rad_s=4.0, beta_rad=-1.0, offset_rate_rad_s=0.0),
    p.SetOffset(offset_rad=-0.25),
    p.Start(),
    p.Stop(),
    p.SetGains(kp_nm_per_rad=3.0, kd_nms_per_rad=0.125, torque_limit_nm=1.0),
    p.Version(0, 1, 1, 5, p.SCHEMA_HASH, 10000),
    p.Telemetry(123, 2, (0.5, -0.25, 0.125, 0.0, 1.0), 0.25, 0.5, 7, 8, 9),
    p.Ack(2, 17),
    p.Refuse(2, 18, int(p.RefuseReason.OUT_OF_RANGE)),
]


@pytest.mark.parametrize("msg", ALL_MESSAGES, ids=lambda m: type(m).__name__)
def test_every_message_round_trips_within_the_radio_frame_size(msg):
    frame = p.encode_frame(msg, seq=200)
    assert len(frame) <= p.MAX_FRAME_BYTES
    assert frame[-1] == 0 and 0 not in frame[:-1]
    assert p.decode_frame(frame[:-1]) == (200, msg)


def body(msg_id, seq, payload, schema=p.SCHEMA_HASH, crc_xor=0):
    b = struct.pack("<HBB", schema, msg_id, seq) + payload
    return p.cobs_encode(b + struct.pack("<H", p.crc16_ccitt_false(b) ^ crc_xor))


@pytest.mark.parametrize(
    ("encoded", "kind"),
    [
        (b"\x09\x11\x22", "cobs"),
        (p.cobs_encode(b"\x01\x02\x03"), "short"),
        (b"\x05" * 80, "oversize"),
        (body(0x04, 0, b"", crc_xor=1), "crc"),
        (body(0x04, 0, b"", schema=p.SCHEMA_HASH ^ 0xFFFF), "schema"),
        (body(0x44, 0, b""), "unknown_id"),
        (body(0x03, 0, b"\x00\x00"), "length"),
    ],
)
def test_every_kind_of_bad_frame_raises_its_kind(encoded, kind):
    with pytest.raises(p.FrameError) as err:
        p.decode_frame(encoded)
    assert err.value.kind == kind


def test_frame_reader_counts_bad_frames_and_keeps_good_ones():
    reader = p.FrameReader()
    stream = b"\x00garbage!\x00" + p.encode_frame(p.Ack(4, 1), 3) + b"\x00"
    assert reader.feed(stream) == [(3, p.Ack(4, 1))]
    assert sum(reader.bad.values()) == 1


def test_validate_rejects_out_of_range_and_non_finite_values():
    p.SetGait().validate()
    with pytest.raises(ValueError, match="amplitude_rad"):
        p.SetGait(amplitude_rad=2.0).validate()
    with pytest.raises(ValueError, match="offset_rad"):
        p.SetOffset(offset_rad=math.nan).validate()


def test_encode_frame_rejects_a_sequence_number_outside_a_byte():
    with pytest.raises(ValueError, match="seq"):
        p.encode_frame(p.Start(), 256)
