// Wiring of the Arduino Nano (see firmware/README.md for the table).
//   D0/RX, D1/TX : XBee DOUT/DIN (through a 5 V -> 3.3 V level shifter on DIN)
//   D2..D6       : servo signal of joints 1..5 (joint 1 = tail joint) = PD2..PD6
//   D7           : "control update busy" test point = PD7 (high while the update runs)
//   A0..A4       : feedback potentiometers of joints 1..5 (analog-feedback servos, optional)
//   A6           : battery through a divider (optional; A6 is analog-only on the Nano)
// The servo pins share port D so the Timer1 interrupt can switch them with one port write.
#pragma once
#include <stdint.h>

#include "config.h"

namespace pins {
// One PORTD bit per joint, joint 1 first: hardware, so listed by hand.
constexpr uint8_t kServoBit[] = {2, 3, 4, 5, 6};
constexpr uint8_t kBusyBit = 7;  // PD7 = D7
constexpr uint8_t kServos = sizeof(kServoBit);
static_assert(kServos == cfg::kJoints,
              "one servo pin per joint: protocol/eelbot.toml n_joints changed, so list the pins "
              "here (and in firmware/README.md)");

constexpr uint8_t servo_mask(uint8_t i = 0) {
  return i == kServos ? 0 : static_cast<uint8_t>((1u << kServoBit[i]) | servo_mask(i + 1));
}
constexpr uint8_t kServoMask = servo_mask();  // the servo bits of PORTD
static_assert((kServoMask & ((1u << kBusyBit) | 0x03u)) == 0,
              "the servo pins must leave PD0/PD1 (the UART) and the busy pin free");

// ADC channel of each analog input of cfg: the joints' potentiometers, joint 1 first, then the
// battery: hardware, so listed by hand.
constexpr uint8_t kAdcChannel[] = {0, 1, 2, 3, 4, 6};
static_assert(sizeof(kAdcChannel) == cfg::kAdcInputs,
              "one ADC channel per joint and one for the battery: protocol/eelbot.toml n_joints "
              "changed, so list the channels here (and in firmware/README.md)");
}  // namespace pins
