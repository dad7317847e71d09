// Board layer of the native build: the caller owns time (lockstep with a simulator), the UART is two
// byte queues, the servos are an array, the analog inputs are numbers the caller sets, the EEPROM
// is a byte array the caller owns (so that it outlives a reset). No I/O, no clock, no globals: many
// instances may coexist.
#pragma once
#include <stdint.h>
#include <string.h>

#include "byte_queue.h"
#include "config.h"

constexpr uint16_t kEepromBytes = 1024;  // the ATmega328P's

struct Hal {
  // Big enough for a burst of host frames between two ticks; the AVR's own RX buffer is 64 bytes.
  ByteQueue<4096> rx;
  ByteQueue<4096> tx;
  uint16_t servo_us[cfg::kJoints] = {};
  uint16_t adc[cfg::kAdcInputs] = {};
  uint8_t* eeprom = nullptr;  // kEepromBytes, erased = 0xFF
  uint32_t busy_edges = 0;    // counts busy_pin() calls, so tests can see control updates happen
  uint32_t adc_sweeps = 0;
  uint32_t watchdog_kicks = 0;
  uint32_t eeprom_writes = 0;  // bytes programmed
  bool eeprom_failing = false;  // writes do not stick (a worn EEPROM)
  bool tx_stalled = false;      // the UART takes no bytes

  bool uart_read(uint8_t& byte) {
    if (rx.empty()) return false;
    byte = rx.pop();
    return true;
  }
  bool uart_can_write() { return !tx_stalled && tx.space() > 0; }
  void uart_write(uint8_t byte) { tx.push(byte); }
  void servo_write_us(const uint16_t* pulse_us) {
    for (uint8_t j = 0; j < cfg::kJoints; ++j) servo_us[j] = pulse_us[j];
  }
  void busy_pin(bool /*on*/) { ++busy_edges; }
  void adc_start() { ++adc_sweeps; }
  const uint16_t* adc_wait() { return adc; }
  void eeprom_load(uint16_t address, uint8_t* out, uint16_t n) const {
    for (uint16_t i = 0; i < n; ++i) out[i] = eeprom_read(static_cast<uint16_t>(address + i));
  }
  // Programming is instant here; a worn EEPROM (eeprom_failing) keeps its old bytes.
  bool eeprom_ready() const { return true; }
  uint8_t eeprom_read(uint16_t address) const {
    return (eeprom != nullptr && address < kEepromBytes) ? eeprom[address] : 0xFF;
  }
  void eeprom_write(uint16_t address, uint8_t byte) {
    ++eeprom_writes;
    if (eeprom != nullptr && address < kEepromBytes && !eeprom_failing) eeprom[address] = byte;
  }
  void kick_watchdog() { ++watchdog_kicks; }
};
