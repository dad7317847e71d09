// libFuzzer target for the stored settings (core/settings_store.h): whatever the EEPROM holds,
// the robot boots settings that pass their checks: the stored ones when a slot is good (and then
// they store back to the same bytes), else exactly the defaults; with two slots, the good one of
// the newer generation.
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "crc32.h"
#include "settings_codec.h"
#include "settings_store.h"
#include "wire.h"

namespace {
void require(bool ok) {
  if (!ok) __builtin_trap();
}

bool same(const eelproto::Settings& a, const eelproto::Settings& b) {
  uint8_t x[eelproto::kSettingsBytes], y[eelproto::kSettingsBytes];
  eelproto::settings_pack(a, x);
  eelproto::settings_pack(b, y);
  return memcmp(x, y, sizeof x) == 0;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  uint8_t image[kSettingsImageBytes];
  memset(image, 0xFF, sizeof image);
  memcpy(image, data, size < sizeof image ? size : sizeof image);
  // Odd first byte: make version and CRC right, so the fuzzer reaches the range checks.
  if (size > sizeof image && (data[sizeof image] & 1)) {
    wire::put_u16(image, eelproto::kSettingsVersion);
    wire::put_u32(image + sizeof image - 4, crc32_iso_hdlc(image, sizeof image - 4));
  }
  eelproto::Settings s;
  uint16_t generation = 0;
  const eelproto::SettingsSource source = settings_from_image(image, s, &generation);
  require(eelproto::settings_check(s) == 0);
  if (source == eelproto::SettingsSource::Eeprom) {
    uint8_t back[kSettingsImageBytes];
    settings_to_image(s, back, generation);
    require(memcmp(back, image, sizeof image) == 0);
  } else {
    require(same(s, eelproto::settings_defaults()));
  }
  // Both slots: the first from the input (as above), the second from what follows it.
  uint8_t eeprom[kSettingsEepromBytes];
  memcpy(eeprom, image, sizeof image);
  memset(eeprom + sizeof image, 0xFF, sizeof image);
  if (size > sizeof image + 1) {
    const size_t rest = size - sizeof image - 1;
    memcpy(eeprom + sizeof image, data + sizeof image + 1, rest < sizeof image ? rest : sizeof image);
    uint8_t* second = eeprom + sizeof image;
    if (data[sizeof image] & 2) {  // make the second slot check out too
      wire::put_u16(second, eelproto::kSettingsVersion);
      wire::put_u32(second + sizeof image - 4, crc32_iso_hdlc(second, sizeof image - 4));
    }
  }
  eelproto::Settings booted, one, two;
  uint16_t gen1 = 0, gen2 = 0;
  const bool valid1 = settings_from_image(eeprom, one, &gen1) == eelproto::SettingsSource::Eeprom;
  const bool valid2 =
      settings_from_image(eeprom + sizeof image, two, &gen2) == eelproto::SettingsSource::Eeprom;
  const StoredSettings stored = settings_from_eeprom(eeprom, booted);
  require(eelproto::settings_check(booted) == 0);
  require((stored.source == eelproto::SettingsSource::Eeprom) == (valid1 || valid2));
  if (!valid1 && !valid2) {
    require(same(booted, eelproto::settings_defaults()));
  } else if (valid1 && valid2) {
    const bool second_newer = static_cast<int16_t>(gen2 - gen1) > 0;
    require(stored.slot == (second_newer ? 1 : 0));
    require(same(booted, second_newer ? two : one));
  } else {
    require(stored.slot == (valid2 ? 1 : 0) && same(booted, valid2 ? two : one));
  }
  return 0;
}
