// Wiring of the Arduino Nano (see firmware/README.md for the table).
//   D0/RX, D1/TX : XBee DOUT/DIN (through a 5 V -> 3.3 V level shifter on DIN)
//   D2..D6       : servo signal of joints 1..5 (joint 1 = tail joint) = PD2..PD6
//   D7           : "control update busy" test point = PD7 (high while the update runs)
// The servo pins share port D so the Timer1 interrupt can switch them with one port write.
#pragma once
#include <stdint.h>

namespace pins {
constexpr uint8_t kServoBit[5] = {2, 3, 4, 5, 6};  // PORTD bits, joint 1 first
constexpr uint8_t kServoMask = 0x7C;                // bits 2..6 of PORTD
constexpr uint8_t kBusyBit = 7;                     // PD7 = D7
}  // namespace pins
