// Board layer of the Arduino Nano. The only directory that includes Arduino.h (in hal_avr.cpp).
#pragma once
#include <stdint.h>

struct Hal {
  // UART to the XBee at eelproto::kBaud, servo timer, busy pin.
  void begin();
  uint32_t now_us();  // micros(): 4 us resolution, wraps every 71.6 min
  bool uart_read(uint8_t& byte);
  bool uart_can_write();  // room in the UART's transmit buffer: writing never blocks the loop
  void uart_write(uint8_t byte);
  void servo_write_us(const uint16_t* pulse_us);
  void busy_pin(bool on);
};
