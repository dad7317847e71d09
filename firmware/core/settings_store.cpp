#include "settings_store.h"

#include "crc32.h"
#include "settings_codec.h"
#include "wire.h"

namespace {
constexpr uint8_t kCrcAt = kSettingsImageBytes - 4;
constexpr uint8_t kSettingsAt = 4;
}  // namespace

void settings_to_image(const eelproto::Settings& s, uint8_t* image, uint16_t generation) {
  wire::put_u16(image, eelproto::kSettingsVersion);
  wire::put_u16(image + 2, generation);
  eelproto::settings_pack(s, image + kSettingsAt);
  wire::put_u32(image + kCrcAt, crc32_iso_hdlc(image, kCrcAt));
}

eelproto::SettingsSource settings_from_image(const uint8_t* image, eelproto::Settings& s,
                                             uint16_t* generation) {
  using eelproto::SettingsSource;
  s = eelproto::settings_defaults();
  bool blank = true;  // an erased EEPROM reads 0xFF everywhere
  for (uint8_t i = 0; i < kSettingsImageBytes; ++i) blank = blank && image[i] == 0xFF;
  if (blank) return SettingsSource::Blank;
  if (wire::get_u16(image) != eelproto::kSettingsVersion) return SettingsSource::OtherVersion;
  if (crc32_iso_hdlc(image, kCrcAt) != wire::get_u32(image + kCrcAt)) {
    return SettingsSource::Corrupt;
  }
  eelproto::Settings stored;
  eelproto::settings_unpack(stored, image + kSettingsAt);
  if (eelproto::settings_check(stored) != 0) return SettingsSource::Corrupt;
  s = stored;
  if (generation != nullptr) *generation = wire::get_u16(image + 2);
  return SettingsSource::Eeprom;
}

StoredSettings settings_from_eeprom(const uint8_t* eeprom, eelproto::Settings& s) {
  using eelproto::SettingsSource;
  uint16_t gen[kSettingsSlots] = {0, 0};
  SettingsSource src[kSettingsSlots];
  for (uint8_t k = 0; k < kSettingsSlots; ++k) {
    src[k] = settings_from_image(eeprom + k * kSettingsImageBytes, s, &gen[k]);
  }
  const bool valid0 = src[0] == SettingsSource::Eeprom, valid1 = src[1] == SettingsSource::Eeprom;
  if (!valid0 && !valid1) {
    s = eelproto::settings_defaults();
    // Say why: a damaged slot matters more than an erased one.
    const SettingsSource why = src[0] == SettingsSource::Blank ? src[1] : src[0];
    return StoredSettings{why, 0, 0};
  }
  const bool newer1 = valid1 && (!valid0 || static_cast<int16_t>(gen[1] - gen[0]) > 0);
  const uint8_t slot = newer1 ? 1 : 0;
  settings_from_image(eeprom + slot * kSettingsImageBytes, s);
  return StoredSettings{SettingsSource::Eeprom, slot, gen[slot]};
}
