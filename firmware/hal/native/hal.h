// Board layer of the native build: the caller owns time (lockstep with a simulator), the UART is two
// byte queues, the servos are an array. No I/O, no clock, no globals: many instances may coexist.
#pragma once
#include <stdint.h>

#include "byte_queue.h"
#include "config.h"

struct Hal {
  // Big enough for a burst of host frames between two ticks; the AVR's own RX buffer is 64 bytes.
  ByteQueue<4096> rx;
  ByteQueue<4096> tx;
  uint16_t servo_us[cfg::kJoints] = {};
  uint32_t busy_edges = 0;  // counts busy_pin() calls, so tests can see control updates happen

  bool uart_read(uint8_t& byte) {
    if (rx.empty()) return false;
    byte = rx.pop();
    return true;
  }
  bool uart_can_write() { return tx.space() > 0; }
  void uart_write(uint8_t byte) { tx.push(byte); }
  void servo_write_us(const uint16_t* pulse_us) {
    for (uint8_t j = 0; j < cfg::kJoints; ++j) servo_us[j] = pulse_us[j];
  }
  void busy_pin(bool /*on*/) { ++busy_edges; }
};
