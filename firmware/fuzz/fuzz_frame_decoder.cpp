// libFuzzer target for the frame decoder and everything a decoded frame can reach.
// The first input byte picks the mode:
//   even: the rest is a raw byte stream from the radio (garbage, partial frames, delimiters);
//   odd:  the rest is a list of [id][seq][len][payload...] records that are wrapped into frames
//         with a valid header and CRCs, so the fuzzer reaches command handling despite the CRCs.
// Every frame a decoder accepts must re-encode to exactly the bytes it came in, and after every
// byte the robot's invariants must hold (checked with __builtin_trap so that the fuzzer reports
// them as crashes): state valid, references finite and inside the joint limit, servo pulses
// inside the servo range, counters consistent.
#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include <string.h>

#include "frame_codec.h"
#include "robot.h"
#include "servo_map.h"
#include "settings_codec.h"

namespace {
void require(bool ok) {
  if (!ok) __builtin_trap();
}

void check_invariants(const Robot& r) {
  require(static_cast<uint8_t>(r.state()) <= 3);
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    const float a = r.gait().alpha_rad()[j];
    require(isfinite(a) && fabsf(a) <= cfg::kJointLimitRad);
    require(isfinite(r.gait().alpha_dot_rad_s()[j]));
    require(r.pulse_us()[j] >= kServoMinUs && r.pulse_us()[j] <= kServoMaxUs);
  }
  require(eelproto::settings_check(r.settings()) == 0);
}

// A second decoder beside the robot's: each frame it accepts must re-encode to the bytes it was
// made of (COBS of a frame this short has one form).
struct Echo {
  FrameDecoder decoder;
  LinkCounters counters{};
  uint8_t seen[eelproto::kMaxFrameBytes * 4];
  size_t n = 0;
  void push(uint8_t byte) {
    if (n < sizeof seen) seen[n] = byte;
    ++n;
    if (decoder.push(byte, counters)) {
      const Frame& f = decoder.frame();
      uint8_t again[eelproto::kMaxFrameBytes];
      const size_t m = encode_frame(f.msg_id, f.seq, f.payload, f.payload_len, again, sizeof again);
      require(m > 0 && m == n && memcmp(again, seen, m) == 0);
    }
    if (byte == 0) n = 0;
  }
};

// The robot's inputs that are not frames: its analog readings (feedback and battery) follow the
// input's bytes too, so that the joint loop and the battery see garbage as well.
uint16_t g_adc[cfg::kAdcInputs];
// An EEPROM that takes every write at once, for the settings writer.
struct InstantEeprom {
  uint8_t bytes[kSettingsEepromBytes];
  bool eeprom_ready() const { return true; }
  uint8_t eeprom_read(uint16_t a) const { return a < sizeof bytes ? bytes[a] : 0xFF; }
  void eeprom_write(uint16_t a, uint8_t v) {
    if (a < sizeof bytes) bytes[a] = v;
  }
} g_eeprom;

void step(Robot& r, Echo& echo, uint8_t byte, uint32_t& now_us) {
  echo.push(byte);
  r.on_rx_byte(byte, now_us);
  g_adc[byte % cfg::kAdcInputs] = static_cast<uint16_t>(byte * 4);
  now_us += 700;  // ~ one byte at 57600 baud (174 us) plus a loop or two; crosses control periods
  if (r.control_due(now_us)) {
    r.control_update(now_us);
    r.joint_update(r.wants_adc() ? g_adc : nullptr);
    r.service(now_us);
  }
  SettingsWriter::Step st;
  while ((st = r.settings_writer().step(g_eeprom)) == SettingsWriter::Step::Writing) {
  }
  if (st != SettingsWriter::Step::Idle) r.save_done(st == SettingsWriter::Step::Written);
  while (!r.tx().empty()) r.tx().pop();
  check_invariants(r);
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  static Robot robot;  // static: the Robot is not small and libFuzzer's stack is
  static Echo echo;
  echo = Echo();
  uint32_t now_us = 0xFFFFFFFFu - 2000000u;  // every run crosses the micros() wrap
  // A robot set up with the defaults saved, so that Start is reachable.
  static uint8_t eeprom[kSettingsEepromBytes];
  memset(eeprom, 0xFF, sizeof eeprom);
  settings_to_image(eelproto::settings_defaults(), eeprom, 1);
  robot.reset(now_us, BootInfo{1, 0, false}, eeprom);
  const bool framed = data[0] & 1;
  ++data;
  --size;
  if (!framed) {
    for (size_t i = 0; i < size; ++i) step(robot, echo, data[i], now_us);
  } else {
    while (size >= 3) {
      const uint8_t id = data[0], seq = data[1];
      size_t len = data[2];
      data += 3;
      size -= 3;
      if (len > size) len = size;
      if (len > frame::kMaxPayload - eelproto::kCommandCrcBytes) {
        len = frame::kMaxPayload - eelproto::kCommandCrcBytes;  // room for a command's CRC-32
      }
      uint8_t out[eelproto::kMaxFrameBytes];
      const size_t n = encode_frame(id, seq, data, static_cast<uint8_t>(len), out, sizeof out);
      require(n > 0 && n <= sizeof out);
      for (size_t i = 0; i < n; ++i) step(robot, echo, out[i], now_us);
      data += len;
      size -= len;
    }
  }
  const LinkCounters& c = robot.counters();
  require(c.frames_ok + c.bad_total() + c.duplicates <= 65535u);
  return 0;
}
