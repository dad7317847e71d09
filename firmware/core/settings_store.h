// The settings as stored in the EEPROM: settings_version:u16 | settings (kSettingsBytes) |
// crc32:u32 over both, at EEPROM address 0. A robot boots the stored settings only when the image
// is of this firmware's settings version, its CRC-32 matches and every value is in range;
// otherwise the defaults, and says why (eelproto::SettingsSource, reported in Status).
#pragma once
#include <stdint.h>

#include "protocol_gen.h"

constexpr uint8_t kSettingsImageBytes = 2 + eelproto::kSettingsBytes + 4;
constexpr uint16_t kSettingsEepromAddress = 0;

// The image of these settings.
void settings_to_image(const eelproto::Settings& s, uint8_t* image);

// The settings of an image (the defaults unless the returned source is EEPROM).
eelproto::SettingsSource settings_from_image(const uint8_t* image, eelproto::Settings& s);
