"""The robot's timing is defined once (protocol/eelbot.toml) and everything runs on it.

The control period (the twin's physics step), the servo frame and the baud are read here from the
definition itself, then compared with what each side actually uses: the constants the firmware
compiles with (a probe compiled against its headers), the periods the flashed AVR image keeps in
simavr, the Version the native firmware reports, the twin's step (eelsim.timing, from its
generated eelsim.firmware_timing), the lockstep's step and the steps a lockstep run takes.
docs/firmware.md, "Timing defined once".
"""

import os
import shutil
import subprocess
import tomllib
from pathlib import Path

import numpy as np
import pytest

from eelhost.wire import protocol
from eelhost.xil import lockstep
from eelhost.xil.native_firmware import NativeFirmware
from eelhost.xil.simavr import BUSY_PIN, SERVO_PINS, AvrSimulator
from eelsim import timing
from eelsim.closed_loop import LoopOptions
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
FIRMWARE = ROOT / "firmware"
DEFINED = {
    name: c["value"]
    for name, c in tomllib.loads((ROOT / "protocol" / "eelbot.toml").read_text())[
        "constants"
    ].items()
}
TIMING = ("control_period_us", "servo_frame_us", "baud")

CPP_PROBE = """
#include <stdio.h>
#include "config.h"
#include "servo_timer1.h"
int main() {
  printf("%lu %lu %lu\\n", (unsigned long)cfg::kControlPeriodUs,
         (unsigned long)servo_timer1::kFrameUs, (unsigned long)eelproto::kBaud);
  return 0;
}
"""
C_PROBE = """
#include <stdio.h>
#include "timing_gen.h"
int main(void) {
  printf("%lu %lu %lu\\n", EEL_CONTROL_PERIOD_US, EEL_SERVO_FRAME_US, EEL_BAUD);
  return 0;
}
"""


def compiled_values(tmp_path, compiler, suffix, source, *flags):
    """Compile a probe against the firmware's headers and return the three numbers it prints."""
    exe = shutil.which(os.environ.get("CXX" if suffix == ".cpp" else "CC", compiler))
    assert exe, f"no {compiler}: the firmware's build needs one"
    src, binary = tmp_path / f"probe{suffix}", tmp_path / f"probe{suffix}.out"
    src.write_text(source)
    subprocess.run([exe, *flags, "-o", str(binary), str(src)], cwd=FIRMWARE, check=True)
    out = subprocess.run([str(binary)], capture_output=True, text=True, check=True).stdout
    return dict(zip(TIMING, map(int, out.split()), strict=True))


def test_the_definition_marks_the_timing_the_twin_shares():
    raw = tomllib.loads((ROOT / "protocol" / "eelbot.toml").read_text())["constants"]
    assert {name for name, c in raw.items() if c.get("twin")} == set(TIMING)


def test_the_firmware_compiles_with_the_defined_timing(tmp_path):
    cpp = compiled_values(tmp_path, "g++", ".cpp", CPP_PROBE,
                          "-std=c++14", "-Icore", "-Iapp", "-Ihal/avr")
    c = compiled_values(tmp_path, "cc", ".c", C_PROBE, "-std=gnu11", "-Itools")
    want = {name: DEFINED[name] for name in TIMING}
    assert cpp == want  # the robot's C++ (core and the AVR board layer)
    assert c == want  # the simavr harness (C)


def test_the_twin_and_the_lockstep_step_at_the_firmwares_control_period():
    period_us = DEFINED["control_period_us"]
    assert timing.PHYSICS_STEP_US == period_us
    assert timing.LoopTiming().dt_s == timing.PHYSICS_STEP_S == period_us / 1e6
    assert LoopOptions().timing.dt_s == timing.PHYSICS_STEP_S
    assert lockstep.DT_US == period_us
    assert protocol.CONTROL_PERIOD_US == period_us
    assert (timing.SERVO_FRAME_US, timing.BAUD) == (DEFINED["servo_frame_us"], DEFINED["baud"])
    assert (protocol.SERVO_FRAME_US, protocol.BAUD) == (timing.SERVO_FRAME_US, timing.BAUD)


def test_the_native_firmware_reports_the_defined_control_period():
    fw = NativeFirmware()
    fw.send(protocol.Hello(), 0)
    fw.tick(0)
    versions = [m for _, m in fw.read_frames() if isinstance(m, protocol.Version)]
    assert [v.control_period_us for v in versions] == [DEFINED["control_period_us"]]


@pytest.mark.firmware_in_loop
def test_a_lockstep_run_ticks_the_firmware_once_every_defined_period():
    robot, scenario = load_robot(), load_scenario("straight").model_copy(update={"duration_s": 0.5})
    res = lockstep.run_firmware_in_loop(robot, scenario, seed=0)
    step_s = np.diff(res.t_s)
    np.testing.assert_allclose(step_s, DEFINED["control_period_us"] * 1e-6, rtol=1e-9)
    telemetry_us = [m.time_us for _, m in res.telemetry]
    assert len(telemetry_us) >= 3
    assert all(t % DEFINED["control_period_us"] == 0 for t in telemetry_us)


@pytest.mark.processor_in_loop
def test_the_flashed_avr_keeps_the_defined_control_period_and_servo_frame():
    sim = AvrSimulator()
    try:
        sim.run_until(300_000)
        pulses = sim.take_pulses()
    finally:
        sim.close()
    busy, joint1 = len(SERVO_PINS), SERVO_PINS.index("D2")
    assert BUSY_PIN == "D7"
    updates = np.array([t for t, pin, _ in pulses if pin == busy])
    frames = np.array([t for t, pin, _ in pulses if pin == joint1])
    assert len(updates) > 20 and len(frames) > 10
    # every period measured from rise to rise on the emulated 16 MHz clock (jitter: a few us)
    np.testing.assert_allclose(np.diff(updates[2:]), DEFINED["control_period_us"], atol=50)
    np.testing.assert_allclose(np.diff(frames[2:]), DEFINED["servo_frame_us"], atol=5)
