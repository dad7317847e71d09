// Writes one settings slot into the EEPROM a byte at a time while the control loop runs
// (docs/firmware.md, "Settings in the EEPROM"). An EEPROM byte takes ~3.4 ms to program; a save
// that waited for each would stop the loop for a third of a second. Each loop pass calls step(),
// whose work is bounded (a pass must stay short, so that no control update waits on it):
//   - while the EEPROM is still programming the byte before, it returns at once;
//   - otherwise it looks at up to kBytesPerStep bytes of the slot, skipping those that already
//     hold their value, and starts programming the first one that differs;
//   - the slot's CRC-32 is computed as the bytes go by (a byte per look, not ~11,000 cycles at
//     once), and its four bytes, the last of the slot, are programmed last: the commit;
//   - then the slot is read back, kBytesPerStep bytes a step.
//
// The board (`Hal`) provides eeprom_ready(), eeprom_read(address) and eeprom_write(address, byte)
// (which starts the programming of one byte and returns).
#pragma once
#include <stdint.h>

#include "crc32.h"
#include "settings_codec.h"
#include "settings_store.h"
#include "wire.h"

class SettingsWriter {
 public:
  enum class Step : uint8_t { Idle, Writing, Written, Failed };
  static constexpr uint8_t kBytesPerStep = 8;

  // Begin writing the slot image of these settings at this generation to this EEPROM address (a
  // write in progress starts over). The image is taken now: later changes wait for the next save.
  void start(const eelproto::Settings& s, uint16_t generation, uint16_t address) {
    wire::put_u16(image_, eelproto::kSettingsVersion);
    wire::put_u16(image_ + 2, generation);
    eelproto::settings_pack(s, image_ + 4);
    crc_ = kCrc32Init;
    address_ = address;
    next_ = 0;
    verified_ = 0;
    busy_ = true;
  }
  bool busy() const { return busy_; }

  // One loop pass: at most one byte started. Written or Failed (read back differs) once, at the end.
  template <typename Hal>
  Step step(Hal& hal) {
    if (!busy_) return Step::Idle;
    if (!hal.eeprom_ready()) return Step::Writing;
    if (next_ < kSettingsImageBytes) {
      for (uint8_t k = 0; k < kBytesPerStep && next_ < kSettingsImageBytes; ++k) {
        if (next_ < kCrcAt) {
          crc_ = crc32_iso_hdlc_step(crc_, image_[next_]);
          if (next_ + 1 == kCrcAt) wire::put_u32(image_ + kCrcAt, ~crc_);
        }
        const uint8_t i = next_++;
        const uint16_t at = static_cast<uint16_t>(address_ + i);
        if (hal.eeprom_read(at) != image_[i]) {
          hal.eeprom_write(at, image_[i]);
          return Step::Writing;
        }
      }
      return Step::Writing;
    }
    for (uint8_t k = 0; k < kBytesPerStep && verified_ < kSettingsImageBytes; ++k, ++verified_) {
      if (hal.eeprom_read(static_cast<uint16_t>(address_ + verified_)) != image_[verified_]) {
        busy_ = false;
        return Step::Failed;
      }
    }
    if (verified_ < kSettingsImageBytes) return Step::Writing;
    busy_ = false;
    return Step::Written;
  }

 private:
  static constexpr uint8_t kCrcAt = kSettingsImageBytes - 4;
  uint8_t image_[kSettingsImageBytes];
  uint32_t crc_ = 0;
  uint16_t address_ = 0;
  uint8_t next_ = 0;
  uint8_t verified_ = 0;
  bool busy_ = false;
};
