// libFuzzer target for the frame decoder and everything a decoded frame can reach.
// The first input byte picks the mode:
//   even: the rest is a raw byte stream from the radio (garbage, partial frames, delimiters);
//   odd:  the rest is a list of [id][seq][len][payload...] records that are wrapped into frames
//         with a valid header and CRC, so the fuzzer reaches command handling despite the CRC.
// After every byte the robot's invariants must hold (checked with __builtin_trap so that the
// fuzzer reports them as crashes): state valid, references finite and inside the joint limit,
// servo pulses inside the calibration, counters consistent.
#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include "frame_codec.h"
#include "robot.h"
#include "servo_map.h"

namespace {
void require(bool ok) {
  if (!ok) __builtin_trap();
}

void check_invariants(const Robot& r) {
  require(static_cast<uint8_t>(r.state()) <= 2);
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    const float a = r.gait().alpha_rad()[j];
    require(isfinite(a) && fabsf(a) <= cfg::kJointLimitRad);
    require(isfinite(r.gait().alpha_dot_rad_s()[j]));
    require(r.pulse_us()[j] >= kServoCalibration[j].min_us);
    require(r.pulse_us()[j] <= kServoCalibration[j].max_us);
  }
}

void step(Robot& r, uint8_t byte, uint32_t& now_us) {
  r.on_rx_byte(byte, now_us);
  now_us += 700;  // ~ one byte at 57600 baud (174 us) plus a loop or two; crosses control periods
  r.service(now_us);
  if (r.control_due(now_us)) r.control_update(now_us);
  while (!r.tx().empty()) r.tx().pop();
  check_invariants(r);
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  static Robot robot;  // static: the Robot is not small and libFuzzer's stack is
  uint32_t now_us = 0xFFFFFFFFu - 2000000u;  // every run crosses the micros() wrap
  robot.reset(now_us);
  const bool framed = data[0] & 1;
  ++data;
  --size;
  if (!framed) {
    for (size_t i = 0; i < size; ++i) step(robot, data[i], now_us);
  } else {
    while (size >= 3) {
      const uint8_t id = data[0], seq = data[1];
      size_t len = data[2];
      data += 3;
      size -= 3;
      if (len > size) len = size;
      if (len > frame::kMaxPayload) len = frame::kMaxPayload;
      uint8_t out[eelproto::kMaxFrameBytes];
      const size_t n = encode_frame(id, seq, data, static_cast<uint8_t>(len), out, sizeof out);
      require(n > 0 && n <= sizeof out);
      for (size_t i = 0; i < n; ++i) step(robot, out[i], now_us);
      data += len;
      size -= len;
    }
  }
  const LinkCounters& c = robot.counters();
  require(c.frames_ok + c.bad_total() + c.duplicates <= 65535u);
  return 0;
}
