// Board layer of the Arduino Nano. The only directory that includes Arduino.h (in hal_avr.cpp).
#pragma once
#include <stdint.h>

#include "boot.h"
#include "config.h"

struct Hal {
  // UART to the XBee at eelproto::kBaud, servo timer, busy pin, ADC. Not yet the watchdog.
  void begin();
  // The hardware watchdog on, last thing in setup(): from then on every pass must kick it. 120 ms
  // without a kick: its interrupt marks the cause in RAM; 120 ms more: the reset.
  void start_watchdog();
  // The reset cause (MCUSR, read before anything else ran) and the resets since power-on.
  BootInfo boot_info();
  uint32_t now_us();  // micros(): 4 us resolution, wraps every 71.6 min
  bool uart_read(uint8_t& byte);
  bool uart_can_write();  // room in the UART's transmit buffer: writing never blocks the loop
  void uart_write(uint8_t byte);
  void servo_write_us(const uint16_t* pulse_us);
  void busy_pin(bool on);
  // One conversion of each analog input (cfg::kAdcInputs), interrupt-driven (~0.1 ms each) while
  // the control update runs; adc_wait() returns the readings (at most 2 ms later).
  void adc_start();
  const uint16_t* adc_wait();
  void eeprom_load(uint16_t address, uint8_t* out, uint16_t n);
  // The EEPROM takes a byte (no write in progress); read one byte (only when ready: a read waits
  // for a write in progress); start programming one byte (~3.4 ms, then ready again). Used by
  // SettingsWriter, one byte a loop pass.
  bool eeprom_ready();
  uint8_t eeprom_read(uint16_t address);
  void eeprom_write(uint16_t address, uint8_t value);
  void kick_watchdog();

 private:
  uint16_t adc_[cfg::kAdcInputs];
};
