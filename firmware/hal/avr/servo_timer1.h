// Servo pulses for the joints from Timer1, written for this robot (Debian ships no Servo
// library). Timer1 runs free at 2 MHz (prescaler 8, 0.5 us per tick); the compare-A interrupt
// raises one servo pin at a time and schedules its falling edge, so the pulses follow each other
// (one per joint, at most 2.5 ms each) and the frame repeats every eelproto::kServoFrameUs (20 ms,
// 50 Hz, what hobby servos expect).
#pragma once
#include <stdint.h>

#include "protocol_gen.h"
#include "servo_map.h"

namespace servo_timer1 {
constexpr uint16_t kFrameUs = eelproto::kServoFrameUs;
constexpr uint16_t kMinUs = kServoMinUs;  // widths are clamped to what any hobby servo accepts
constexpr uint16_t kMaxUs = kServoMaxUs;
static_assert(static_cast<uint32_t>(eelproto::kNJoints) * kMaxUs < kFrameUs,
              "the joints' longest pulses, one after the other, must fit in one servo frame");

// Configure the pins and Timer1; every servo starts at 1500 us (centre).
void begin();
// New widths for joints 1..N (eelproto::kNJoints); they take effect at each pulse's next rising
// edge.
void write_us(const uint16_t* width_us);
}  // namespace servo_timer1
