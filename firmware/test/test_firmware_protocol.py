"""The protocol definition, its generator's check, and the generated Python codec."""

import importlib.util
import math
import re
import struct
import subprocess
import sys
import zlib
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


OUTPUTS = (
    "CPP_OUT", "PY_OUT", "SIM_TIMING_OUT", "C_TIMING_OUT", "NATIVE_H_OUT", "DOCS_OUT",
    "PLATFORMIO_OUT",
)


def outputs_copied_to(tmp_path, gen, monkeypatch):
    """Point the generator at copies of its outputs in tmp_path; return name -> copy."""
    copies = {}
    for name in OUTPUTS:
        copy = tmp_path / getattr(gen, name).name
        copy.write_text(getattr(gen, name).read_text())
        monkeypatch.setattr(gen, name, copy)
        copies[name] = copy
    monkeypatch.setattr(gen, "ROOT", tmp_path)
    return copies


@pytest.mark.parametrize(
    ("output", "old", "new"),
    [
        ("CPP_OUT", "kBaud = 57600UL", "kBaud = 9600UL"),
        ("PY_OUT", "BAUD = 57600", "BAUD = 9600"),
        ("SIM_TIMING_OUT", "CONTROL_PERIOD_US = 10000", "CONTROL_PERIOD_US = 20000"),
        ("C_TIMING_OUT", "#define EEL_SERVO_FRAME_US 20000UL", "#define EEL_SERVO_FRAME_US 0UL"),
        ("NATIVE_H_OUT", "#define EEL_JOINTS ", "#define EEL_JOINTS 1"),
        ("DOCS_OUT", "| 0x04 | Start |", "| 0x07 | Start |"),
        ("PLATFORMIO_OUT", "monitor_speed = 57600", "monitor_speed = 115200"),
    ],
)
def test_check_fails_when_a_rendered_file_drifts(tmp_path, monkeypatch, capsys, output, old, new):
    gen = load_generator()
    copies = outputs_copied_to(tmp_path, gen, monkeypatch)
    text = copies[output].read_text()
    assert old in text
    copies[output].write_text(text.replace(old, new, 1))
    before = {name: copy.read_text() for name, copy in copies.items()}
    assert gen.main(["--check"]) == 1
    assert f"{copies[output].name} differs" in capsys.readouterr().err
    assert {name: copy.read_text() for name, copy in copies.items()} == before  # writes nothing
    assert gen.main([]) == 0 and gen.main(["--check"]) == 0  # and regenerating repairs it


def test_check_names_a_file_that_lost_its_generated_region(tmp_path, monkeypatch, capsys):
    gen = load_generator()
    copies = outputs_copied_to(tmp_path, gen, monkeypatch)
    docs = copies["DOCS_OUT"]
    docs.write_text(docs.read_text().replace("<!-- END GENERATED: messages -->\n", ""))
    assert gen.main(["--check"]) == 1
    err = capsys.readouterr().err
    assert "firmware.md" in err and "END GENERATED: messages" in err


def with_constant(text, name, value):
    """The definition with one constant's value changed."""
    head = f"[constants.{name}]\nvalue = "
    start = text.index(head) + len(head)
    return text[:start] + str(value) + text[text.index("\n", start) :]


def test_the_joint_count_is_set_in_one_place_and_reaches_every_output(tmp_path, monkeypatch):
    gen = load_generator()
    six = tmp_path / "six.toml"
    six.write_text(with_constant((ROOT / "protocol" / "eelbot.toml").read_text(), "n_joints", 6))
    monkeypatch.setattr(gen, "DEFINITION", six)
    out = outputs_copied_to(tmp_path, gen, monkeypatch)
    assert gen.main([]) == 0
    cpp = out["CPP_OUT"].read_text()
    assert "constexpr uint8_t kNJoints = 6;" in cpp and "float alpha_rad[kNJoints];" in cpp
    # one more joint: an f32 reference and an i16 measured angle
    assert f"kPayloadBytes = {p.Telemetry.PAYLOAD_BYTES + 4 + 2};" in cpp
    assert "\nN_JOINTS = 6\n" in out["PY_OUT"].read_text()
    assert "\n#define EEL_JOINTS 6\n" in out["NATIVE_H_OUT"].read_text()
    docs = out["DOCS_OUT"].read_text()
    assert "| `n_joints` | 6 |" in docs and "alpha_rad f32 x n_joints (6)" in docs
    assert "trim_us` | i16 x n_joints (6)" in docs
    assert f"**0x{p.SCHEMA_HASH:04X}**" not in docs  # the telemetry layout changed the hash
    assert f"**0x{p.SETTINGS_VERSION:04X}**" not in docs  # and the settings' layout


def test_a_body_whose_telemetry_outgrows_a_radio_frame_is_refused(tmp_path):
    gen = load_generator()
    seven = tmp_path / "seven.toml"
    seven.write_text(with_constant((ROOT / "protocol" / "eelbot.toml").read_text(), "n_joints", 7))
    with pytest.raises(gen.DefinitionError, match="Telemetry: 70 encoded bytes exceed"):
        gen.load(seven)


def test_periods_are_shared_constants_outside_the_schema_hash(tmp_path):
    gen = load_generator()
    slower = tmp_path / "slower.toml"
    text = (ROOT / "protocol" / "eelbot.toml").read_text()
    slower.write_text(with_constant(text, "link_timeout_us", 2_000_000))
    d = gen.load(slower)
    assert d["schema_hash"] == p.SCHEMA_HASH
    assert "constexpr uint32_t kLinkTimeoutUs = 2000000UL;" in gen.render_cpp(d)
    # docs quote the constant ({link_timeout_us}), so they follow it
    assert "No valid frame for 2 s while running" in gen.render_cpp(d)
    assert "No valid frame for 1 s while running" in gen.render_cpp(gen.load())


def test_the_control_period_is_set_in_one_place_and_reaches_the_firmware_and_the_twin(
    tmp_path, monkeypatch
):
    gen = load_generator()
    faster = tmp_path / "faster.toml"
    text = (ROOT / "protocol" / "eelbot.toml").read_text()
    faster.write_text(with_constant(text, "control_period_us", 5000))
    monkeypatch.setattr(gen, "DEFINITION", faster)
    out = outputs_copied_to(tmp_path, gen, monkeypatch)
    assert gen.main([]) == 0
    assert "constexpr uint32_t kControlPeriodUs = 5000UL;" in out["CPP_OUT"].read_text()
    assert "\nCONTROL_PERIOD_US = 5000\n" in out["PY_OUT"].read_text()
    assert "\nCONTROL_PERIOD_US = 5000\n" in out["SIM_TIMING_OUT"].read_text()
    assert "\n#define EEL_CONTROL_PERIOD_US 5000UL\n" in out["C_TIMING_OUT"].read_text()
    assert "| `control_period_us` | 5000 |" in out["DOCS_OUT"].read_text()
    assert gen.load(faster)["schema_hash"] == p.SCHEMA_HASH  # a period, not a wire change


def test_only_the_constants_marked_twin_reach_the_twins_module():
    gen = load_generator()
    d = gen.load()
    twin = gen.render_sim_timing(d)
    assert "\nBAUD = 57600\n" in twin and "\nSERVO_FRAME_US = 20000\n" in twin
    assert "N_JOINTS" not in twin and "LINK_TIMEOUT_US" not in twin
    imports = [line for line in twin.splitlines() if line.startswith(("import ", "from "))]
    assert imports == ["from __future__ import annotations"]  # the twin imports nothing of eelhost


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


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("id = 0x05", "id = 0x04", "unique"),
        (
            "[constants.n_joints]\nvalue = 5",
            "[constants.n_joints]\nvalue = 15",
            "exceed max_frame_bytes",
        ),
        (
            '"alpha_rad", type = "f32", count = "n_joints"',
            '"alpha_rad", type = "f32", count = "n_links"',
            "Telemetry.alpha_rad: count names 'n_links'",
        ),
        ("key = 2\n", "key = 1\n", "setting keys must be unique"),
        ("min = -500\nmax = 500", "min = -500.5\nmax = 500", "setting trim_us: an integer setting"),
        ("min = 0\nmax = 65535", "min = 0\nmax = 65536", "setting radio_id: an integer setting"),
        ('from = "SetGains.kd_nms_per_rad"', 'from = "SetGains.kd"', "from names no ranged field"),
        ('["HW_WATCHDOG", 8,', '["HW_WATCHDOG", 6,', "enum Flags: each flag must be one bit"),
        ("{telemetry_period_us}", "{telemetry_rate}", "Telemetry: the doc quotes {telemetry_rate}"),
        ("[constants.baud]\nvalue = 57600", "[constants.baud]\nvalue = -1", "constants.baud"),
        ("twin = true\n", "twin = 1\n", "twin must be true or false"),
        (
            "max = 1.5, default = 0.5",
            "default = 0.5",
            "SetGait.amplitude_rad: give min, max and default",
        ),
    ],
)
def test_definition_errors_name_what_is_wrong_and_where(tmp_path, old, new, message):
    gen = load_generator()
    text = (ROOT / "protocol" / "eelbot.toml").read_text()
    assert old in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(old, new))
    with pytest.raises(gen.DefinitionError, match=re.escape(message)):
        gen.load(bad)


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
    p.GetSetting(p.SettingKey.TRIM_US, 4),
    p.SetSetting(p.SettingKey.ADC_COUNTS_PER_RAD, 2, 97.5),
    p.SaveSettings(),
    p.DefaultSettings(),
    p.GetStatus(),
    p.Version(0, 1, 1, p.N_JOINTS, p.SCHEMA_HASH, p.CONTROL_PERIOD_US, p.SETTINGS_VERSION, 7),
    p.Telemetry(
        123,
        2,
        int(p.Flags.FADING | p.Flags.JOINT_FEEDBACK),
        tuple(0.125 * j - 0.25 for j in range(p.N_JOINTS)),
        0.25,
        0.5,
        7,
        8,
        9,
        tuple(-32768 + 9000 * j for j in range(p.N_JOINTS)),
    ),
    p.Ack(2, 17),
    p.Refuse(2, 18, int(p.RefuseReason.OUT_OF_RANGE)),
    p.Setting(p.SettingKey.RADIO_ID, 0, 65535.0),
    p.Status(*range(1, 7), 6.5, *range(7, 21)),
]


@pytest.mark.parametrize("msg", ALL_MESSAGES, ids=lambda m: type(m).__name__)
def test_every_message_round_trips_within_the_radio_frame_size(msg):
    frame = p.encode_frame(msg, seq=200)
    assert len(frame) <= p.MAX_FRAME_BYTES
    assert frame[-1] == 0 and 0 not in frame[:-1]
    assert p.decode_frame(frame[:-1]) == (200, msg)


def body(msg_id, seq, payload, schema=p.SCHEMA_HASH, crc_xor=0, crc32_xor=None):
    b = struct.pack("<HBB", schema, msg_id, seq) + payload
    if crc32_xor is not None:
        b += struct.pack("<I", zlib.crc32(b) ^ crc32_xor)
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
        (body(0x03, 0, b"\x00\x00\x00\x00"), "length"),  # a command without its CRC-32
        (body(0x03, 0, b"\x00\x00\x00\x00", crc32_xor=0x100), "crc32"),
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
