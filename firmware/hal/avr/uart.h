// UART0 to the XBee, interrupt-driven, written for this robot rather than taken from the Arduino
// core: its HardwareSerial runs 57600 baud without U2X (UBRR 16: +2.1 % error, kept there for old
// bootloaders), costs ~1 KB of flash, and cannot say when it loses bytes. This one runs U2X,
// UBRR 34 (-0.8 %), as protocol/eelbot.toml's baud says.
#pragma once
#include <stdint.h>

namespace uart {
// 8N1 at eelproto::kBaud; receive and transmit by interrupt.
void begin();
// A received byte, if one is waiting (64 bytes are buffered).
bool read(uint8_t& byte);
// Room in the transmit buffer (32 bytes): write() then never waits.
bool can_write();
void write(uint8_t byte);
}  // namespace uart
