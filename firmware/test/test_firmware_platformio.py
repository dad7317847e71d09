"""platformio.ini parses offline with `pio project config` and describes both builds."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def pio_executable():
    beside_python = Path(sys.executable).with_name("pio")
    found = beside_python if beside_python.exists() else shutil.which("pio")
    assert found, "pio not found: run scripts/setup.sh (platformio is a dev dependency)"
    return str(found)


def project_config(tmp_path):
    env = dict(os.environ, PLATFORMIO_CORE_DIR=str(tmp_path / "pio-core"))
    proc = subprocess.run(
        [pio_executable(), "project", "config", "--json-output", "-d", str(ROOT)],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip() == ""  # pio warns about unknown options on stderr
    return {section: dict(items) for section, items in json.loads(proc.stdout)}


def test_platformio_ini_has_the_nano_and_native_environments(tmp_path):
    cfg = project_config(tmp_path)
    nano, native = cfg["env:nanoatmega328"], cfg["env:native"]
    assert (nano["platform"], nano["board"], nano["framework"]) == (
        "atmelavr",
        "nanoatmega328",
        ["arduino"],
    )
    assert nano["monitor_speed"] == 57600
    assert native["platform"] == "native"
    assert "-Werror" in nano["build_src_flags"][0]
    assert cfg["platformio"]["default_envs"] == ["nanoatmega328"]


def test_platformio_source_filters_and_include_paths_exist(tmp_path):
    cfg = project_config(tmp_path)
    src = Path(cfg["platformio"]["src_dir"])
    assert src == ROOT / "firmware"
    for env in ("env:nanoatmega328", "env:native"):
        for token in cfg[env]["build_src_filter"][0].split():
            if token.startswith("+<"):
                pattern = token[2:-1]
                assert list(src.glob(pattern.rstrip("/") or ".")), f"{env}: {token} matches nothing"
        for flag in cfg[env]["build_flags"][0].split():
            if flag.startswith("-I"):
                assert (ROOT / flag[2:]).is_dir(), f"{env}: {flag} is not a directory"
    # The AVR build must not see the native board layer, nor the tests (and vice versa).
    assert "hal/native" not in cfg["env:nanoatmega328"]["build_src_filter"][0]
    assert "hal/avr" not in cfg["env:native"]["build_src_filter"][0]
