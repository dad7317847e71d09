// Servo pulses for the five joints from Timer1, written for this robot (Debian ships no Servo
// library). Timer1 runs free at 2 MHz (prescaler 8, 0.5 us per tick); the compare-A interrupt
// raises one servo pin at a time and schedules its falling edge, so the pulses follow each other
// (5 x at most 2.5 ms) and the frame repeats every 20 ms (50 Hz, what hobby servos expect).
#pragma once
#include <stdint.h>

namespace servo_timer1 {
constexpr uint16_t kFrameUs = 20000;
constexpr uint16_t kMinUs = 500;   // widths are clamped to what any hobby servo accepts
constexpr uint16_t kMaxUs = 2500;

// Configure the pins and Timer1; every servo starts at 1500 us (centre).
void begin();
// New widths for joints 1..5; they take effect at each pulse's next rising edge.
void write_us(const uint16_t* width_us);
}  // namespace servo_timer1
