#include <Arduino.h>

#include "hal.h"
#include "pins.h"
#include "protocol_gen.h"
#include "servo_timer1.h"

void Hal::begin() {
  Serial.begin(eelproto::kBaud);  // 57600: U2X, UBRR 34, -0.8 % error at 16 MHz
  servo_timer1::begin();
  DDRD |= _BV(pins::kBusyBit);
  PORTD &= static_cast<uint8_t>(~_BV(pins::kBusyBit));
}

uint32_t Hal::now_us() { return micros(); }

bool Hal::uart_read(uint8_t& out) {
  const int c = Serial.read();
  if (c < 0) return false;
  out = static_cast<uint8_t>(c);
  return true;
}

bool Hal::uart_can_write() { return Serial.availableForWrite() > 0; }

void Hal::uart_write(uint8_t b) { Serial.write(b); }

void Hal::servo_write_us(const uint16_t* pulse_us) { servo_timer1::write_us(pulse_us); }

void Hal::busy_pin(bool on) {
  if (on) {
    PORTD |= _BV(pins::kBusyBit);
  } else {
    PORTD &= static_cast<uint8_t>(~_BV(pins::kBusyBit));
  }
}
