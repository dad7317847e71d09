#include "settings_store.h"

#include "crc32.h"
#include "settings_codec.h"
#include "wire.h"

namespace {
constexpr uint8_t kCrcAt = kSettingsImageBytes - 4;
}  // namespace

void settings_to_image(const eelproto::Settings& s, uint8_t* image) {
  wire::put_u16(image, eelproto::kSettingsVersion);
  eelproto::settings_pack(s, image + 2);
  wire::put_u32(image + kCrcAt, crc32_iso_hdlc(image, kCrcAt));
}

eelproto::SettingsSource settings_from_image(const uint8_t* image, eelproto::Settings& s) {
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
  eelproto::settings_unpack(stored, image + 2);
  if (eelproto::settings_check(stored) != 0) return SettingsSource::Corrupt;
  s = stored;
  return SettingsSource::Eeprom;
}
