// What the board knows at boot, and the count of resets since power-on (docs/firmware.md,
// "Health").
#pragma once
#include <stdint.h>

#include "protocol_gen.h"

struct BootInfo {
  uint8_t reset_flags;  // eelproto::ResetFlags bits (the AVR's MCUSR), 0 when unknown
  uint16_t resets;      // resets since power-on
  bool hw_watchdog;     // the board runs a hardware watchdog
};

// Kept in RAM that a reset leaves alone but a power cycle scrambles (the AVR's .noinit section).
// The check tells a count from the random bits RAM powers up with (a false match: 1 in 2^32).
struct ResetRecord {
  uint16_t resets;
  uint32_t check;
};

// The reset cause when the MCUSR bits were found cleared, as a bootloader that reads and clears
// them leaves it (docs/firmware.md, "Reset cause"): WATCHDOG when the watchdog's interrupt, which
// comes just before its reset, left its mark in RAM that a reset keeps; POWER_ON when that RAM did
// not survive (the reset record does not check out); otherwise 0, unknown (the reset pin or a
// brown-out that kept the RAM). Bits that the MCUSR still held are taken as they are.
inline uint8_t infer_reset_flags(uint8_t mcusr, bool watchdog_marked, const ResetRecord& r) {
  constexpr uint32_t kMagic = 0x5EB0071CUL;  // count_reset's
  if (mcusr != 0) return mcusr;
  if (watchdog_marked) return static_cast<uint8_t>(eelproto::ResetFlags::Watchdog);
  if (r.check != (kMagic ^ r.resets)) return static_cast<uint8_t>(eelproto::ResetFlags::PowerOn);
  return 0;
}

// Count this boot: back to 0 at a power-on (flag POWER_ON, or a record that does not check out),
// else one more. Returns the resets since power-on.
inline uint16_t count_reset(ResetRecord& r, uint8_t reset_flags) {
  constexpr uint32_t kMagic = 0x5EB0071CUL;
  const bool power_on = (reset_flags & static_cast<uint8_t>(eelproto::ResetFlags::PowerOn)) != 0;
  if (power_on || r.check != (kMagic ^ r.resets)) {
    r.resets = 0;
  } else {
    r.resets = static_cast<uint16_t>(r.resets + 1);
  }
  r.check = kMagic ^ r.resets;
  return r.resets;
}
