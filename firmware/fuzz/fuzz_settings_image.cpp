// libFuzzer target for the stored settings (core/settings_store.h): whatever the EEPROM holds,
// the robot boots settings that pass their checks: the stored ones when the image is good (and
// then they store back to the same bytes), else exactly the defaults.
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
  const eelproto::SettingsSource source = settings_from_image(image, s);
  require(eelproto::settings_check(s) == 0);
  if (source == eelproto::SettingsSource::Eeprom) {
    uint8_t back[kSettingsImageBytes];
    settings_to_image(s, back);
    require(memcmp(back, image, sizeof image) == 0);
  } else {
    require(same(s, eelproto::settings_defaults()));
  }
  return 0;
}
