#include <Arduino.h>
#include <avr/eeprom.h>
#include <avr/wdt.h>
#include <util/atomic.h>

#include "hal.h"
#include "pins.h"
#include "protocol_gen.h"
#include "servo_map.h"
#include "servo_timer1.h"
#include "uart.h"

namespace {
// RAM the C runtime does not clear, so that a reset (not a power cycle) leaves it as it was.
uint8_t g_mcusr_at_boot __attribute__((section(".noinit")));
ResetRecord g_reset_record __attribute__((section(".noinit")));
// Set by the watchdog's interrupt just before the watchdog resets the AVR: the cause survives a
// bootloader that clears MCUSR. A 32-bit mark, so that RAM's random state at power-on is taken
// for it with probability 2^-32.
uint32_t g_watchdog_mark __attribute__((section(".noinit")));
constexpr uint32_t kWatchdogFired = 0xDEAD50F7UL;

volatile uint16_t g_adc[cfg::kAdcInputs];
volatile uint8_t g_adc_next;  // input being converted; cfg::kAdcInputs when the sweep is done

// 16 MHz / 128 = 125 kHz, within the 50..200 kHz of full 10-bit resolution: 13 ADC clocks, 104 us
// a conversion. Reference AVCC (REFS0).
constexpr uint8_t kAdcControl = _BV(ADEN) | _BV(ADIE) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);
constexpr uint32_t kAdcTimeoutUs = 2000;
}  // namespace

// Runs before the C runtime sets RAM up (section .init3, right after the stack): the reset cause
// must be read before anything clears it, and the watchdog stopped, because after a watchdog
// reset it stays on (WDRF forces WDE) at its shortest period, 16 ms. Behind a bootloader that
// clears MCUSR the bits read 0 (docs/firmware.md, "Reset cause"); Optiboot 4.6 and later leave
// them in r2 (build with `make BOOTLOADER=optiboot`), which nothing before .init3 touches.
extern "C" void eel_capture_reset_cause() __attribute__((naked, used, section(".init3")));
void eel_capture_reset_cause() {
  uint8_t flags = MCUSR;
#ifdef EEL_BOOTLOADER_OPTIBOOT
  if (flags == 0) __asm__ __volatile__("mov %0, r2" : "=r"(flags));
#endif
  g_mcusr_at_boot = flags;
  MCUSR = 0;
  wdt_disable();
}

// The main loop stopped kicking the watchdog for 120 ms: mark it in RAM that a reset keeps. The
// watchdog, now in reset mode (the hardware clears WDIE as this runs; cleared here as well), resets
// the AVR 120 ms later unless the loop kicks it meanwhile. Returning keeps the servo interrupt
// (and the pulses it holds) running until then.
ISR(WDT_vect) {
  g_watchdog_mark = kWatchdogFired;
  WDTCSR &= static_cast<uint8_t>(~_BV(WDIE));
}

// One conversion done: store it, start the next input's.
ISR(ADC_vect) {
  const uint8_t i = g_adc_next;
  g_adc[i] = ADC;
  const uint8_t next = static_cast<uint8_t>(i + 1);
  g_adc_next = next;
  if (next < cfg::kAdcInputs) {
    ADMUX = static_cast<uint8_t>(_BV(REFS0) | pins::kAdcChannel[next]);
    ADCSRA = kAdcControl | _BV(ADSC);
  }
}

void Hal::begin() {
  uart::begin();
  servo_timer1::begin();
  DDRD |= _BV(pins::kBusyBit);
  PORTD &= static_cast<uint8_t>(~_BV(pins::kBusyBit));
  g_adc_next = cfg::kAdcInputs;
  ADCSRA = kAdcControl;
}

// Interrupt and reset mode: the interrupt after 120 ms without a kick (WDT_vect marks the cause),
// the reset after 120 ms more: a hung loop resets 240 ms after its last pass.
void Hal::start_watchdog() {
  wdt_enable(WDTO_120MS);
  WDTCSR |= _BV(WDIE);
}

// A kick also arms the interrupt again and wipes its mark, in case a late pass came between
// interrupt and reset: the loop runs, and no reset is on its way.
void Hal::kick_watchdog() {
  wdt_reset();
  WDTCSR |= _BV(WDIE);
  g_watchdog_mark = 0;
}


BootInfo Hal::boot_info() {
  // MCUSR's PORF, EXTRF, BORF, WDRF are the bits of eelproto::ResetFlags.
  const bool marked = g_watchdog_mark == kWatchdogFired;
  g_watchdog_mark = 0;
  const uint8_t flags = infer_reset_flags(g_mcusr_at_boot & 0x0F, marked, g_reset_record);
  return BootInfo{flags, count_reset(g_reset_record, flags), true};
}

uint32_t Hal::now_us() { return micros(); }

bool Hal::uart_read(uint8_t& out) { return uart::read(out); }

bool Hal::uart_can_write() { return uart::can_write(); }

void Hal::uart_write(uint8_t b) { uart::write(b); }

void Hal::servo_write_us(const uint16_t* pulse_us) { servo_timer1::write_us(pulse_us); }

void Hal::busy_pin(bool on) {
  if (on) {
    PORTD |= _BV(pins::kBusyBit);
  } else {
    PORTD &= static_cast<uint8_t>(~_BV(pins::kBusyBit));
  }
}

void Hal::adc_start() {
  g_adc_next = 0;
  ADMUX = static_cast<uint8_t>(_BV(REFS0) | pins::kAdcChannel[0]);
  ADCSRA = kAdcControl | _BV(ADSC);
}

const uint16_t* Hal::adc_wait() {
  const uint32_t t0 = micros();
  while (g_adc_next < cfg::kAdcInputs && micros() - t0 < kAdcTimeoutUs) {
  }
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    for (uint8_t i = 0; i < cfg::kAdcInputs; ++i) adc_[i] = g_adc[i];
  }
  return adc_;
}

void Hal::eeprom_load(uint16_t address, uint8_t* out, uint16_t n) {
  eeprom_read_block(out, reinterpret_cast<const void*>(address), n);
}

bool Hal::eeprom_ready() { return eeprom_is_ready(); }

uint8_t Hal::eeprom_read(uint16_t address) {
  return eeprom_read_byte(reinterpret_cast<const uint8_t*>(address));
}

// avr-libc waits for the EEPROM to be ready first (it is: SettingsWriter asked), sets the address
// and data, and starts the programming with interrupts off for the 4-cycle EEMPE/EEPE sequence.
void Hal::eeprom_write(uint16_t address, uint8_t value) {
  eeprom_write_byte(reinterpret_cast<uint8_t*>(address), value);
}
