// The settings as stored in the EEPROM, power-safe (docs/firmware.md, "Settings in the EEPROM").
//
// Two slots, each settings_version:u16 | generation:u16 | settings (kSettingsBytes) | crc32:u32
// over all before it, side by side from EEPROM address 0. A save writes the slot not in use, in
// address order, so the CRC-32 is written last: until its last byte is in, the slot does not check
// out and the other slot (the settings before) is the one that boots. At boot the valid slot of the
// newer generation wins. A slot is valid only when it is of this firmware's settings version, its
// CRC-32 matches and every value is in range; with no valid slot the robot boots the defaults and
// says why (eelproto::SettingsSource, reported in Status).
#pragma once
#include <stdint.h>

#include "protocol_gen.h"

constexpr uint8_t kSettingsImageBytes = 2 + 2 + eelproto::kSettingsBytes + 4;  // one slot
constexpr uint8_t kSettingsSlots = 2;
constexpr uint16_t kSettingsEepromAddress = 0;
constexpr uint16_t kSettingsEepromBytes = kSettingsSlots * kSettingsImageBytes;  // both slots

constexpr uint16_t settings_slot_address(uint8_t slot) {
  return static_cast<uint16_t>(kSettingsEepromAddress + slot * kSettingsImageBytes);
}

// The slot image of these settings at this generation.
void settings_to_image(const eelproto::Settings& s, uint8_t* image, uint16_t generation = 1);

// The settings of one slot image (the defaults unless the returned source is EEPROM), and its
// generation when valid.
eelproto::SettingsSource settings_from_image(const uint8_t* image, eelproto::Settings& s,
                                             uint16_t* generation = nullptr);

// What boot found in the two slots.
struct StoredSettings {
  eelproto::SettingsSource source;  // Eeprom when a slot was valid
  uint8_t slot;                     // the slot booted (valid only with source Eeprom)
  uint16_t generation;              // its generation (0 with none)
};

// The settings of both slots (kSettingsEepromBytes read from kSettingsEepromAddress): the valid
// slot of the newer generation (serial-number order, so the counter may wrap), else the defaults.
StoredSettings settings_from_eeprom(const uint8_t* eeprom, eelproto::Settings& s);
