#include "servo_timer1.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

#include "pins.h"

namespace {
using pins::kServos;
constexpr uint16_t kTicksPerUs = 2;  // 16 MHz / 8
static_assert(static_cast<uint32_t>(servo_timer1::kFrameUs) * kTicksPerUs <= 0xFFFFu,
              "a servo frame must fit in Timer1's 16 bits");
constexpr uint16_t kFrameTicks = servo_timer1::kFrameUs * kTicksPerUs;

volatile uint16_t g_width_ticks[kServos];
volatile uint8_t g_next;        // servo whose pulse starts at the next compare match
volatile uint16_t g_used_ticks;  // ticks spent on pulses in this frame

// Port masks, not bit numbers: a variable shift on the AVR takes a loop, and a variable delay before
// the edge would make the widths depend on the joint.
struct ServoMasks {
  uint8_t of_servo[kServos];
  constexpr ServoMasks() : of_servo() {
    for (uint8_t i = 0; i < kServos; ++i) {
      of_servo[i] = static_cast<uint8_t>(1u << pins::kServoBit[i]);
    }
  }
};
constexpr ServoMasks g_bit;
}  // namespace

// Each match ends the pulse in progress (if any) and starts the next one, or idles until the frame
// ends. OCR1A moves forward modulo 2^16, like TCNT1 itself, so no reset of the counter is needed
// and Timer1 stays free for measuring.
// The pin change comes first and in a single port write: the previous pulse ends and the next one
// starts in the same instruction, at the same delay after the match every time, so the widths come
// out exact (measured in simavr: within 1 tick, except when another interrupt delays this one).
ISR(TIMER1_COMPA_vect) {
  const uint8_t i = g_next;
  const uint8_t others = static_cast<uint8_t>(PORTD & ~pins::kServoMask);
  PORTD = (i < kServos) ? static_cast<uint8_t>(others | g_bit.of_servo[i]) : others;
  if (i < kServos) {
    const uint16_t w = g_width_ticks[i];
    OCR1A += w;
    g_used_ticks += w;
    g_next = static_cast<uint8_t>(i + 1);
  } else {
    OCR1A += static_cast<uint16_t>(kFrameTicks - g_used_ticks);
    g_used_ticks = 0;
    g_next = 0;
  }
}

namespace servo_timer1 {

void begin() {
  for (uint8_t i = 0; i < kServos; ++i) g_width_ticks[i] = 1500 * kTicksPerUs;
  g_next = 0;
  g_used_ticks = 0;
  PORTD &= static_cast<uint8_t>(~pins::kServoMask);
  DDRD |= pins::kServoMask;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    TCCR1A = 0;                      // normal mode: count 0..0xFFFF, no hardware pin output
    TCCR1B = _BV(CS11);              // clk/8
    OCR1A = static_cast<uint16_t>(TCNT1 + 100);
    TIFR1 = _BV(OCF1A);              // no stale match
    TIMSK1 |= _BV(OCIE1A);
  }
}

void write_us(const uint16_t* width_us) {
  for (uint8_t i = 0; i < kServos; ++i) {
    uint16_t w = width_us[i];
    if (w < kMinUs) w = kMinUs;
    if (w > kMaxUs) w = kMaxUs;
    // A 16-bit store is two byte stores on the AVR: keep the ISR from reading half of one.
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { g_width_ticks[i] = static_cast<uint16_t>(w * kTicksPerUs); }
  }
}

}  // namespace servo_timer1
