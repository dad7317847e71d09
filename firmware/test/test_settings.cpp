// The settings: their generic codec over the settings table (core/settings_codec.h) and their
// EEPROM image (core/settings_store.h).
#include <math.h>
#include <string.h>

#include "check.h"
#include "config.h"
#include "crc32.h"
#include "frames.h"
#include "message_codec.h"
#include "settings_codec.h"
#include "settings_store.h"

namespace {
using eelproto::SettingKey;
using eelproto::SettingsSource;

uint8_t key(SettingKey k) { return static_cast<uint8_t>(k); }
uint8_t why(eelproto::RefuseReason r) { return static_cast<uint8_t>(r); }

bool same(const eelproto::Settings& a, const eelproto::Settings& b) {
  uint8_t x[eelproto::kSettingsBytes], y[eelproto::kSettingsBytes];
  eelproto::settings_pack(a, x);
  eelproto::settings_pack(b, y);
  return memcmp(x, y, sizeof x) == 0;
}

// Every element of every setting set to a value of its own, inside its range.
eelproto::Settings all_changed() {
  eelproto::Settings s = eelproto::settings_defaults();
  for (uint8_t k = 1; k <= eelproto::kSettingCount; ++k) {
    eelproto::SettingInfo info;
    flash_read(&info, &eelproto::kSettingTable[k - 1], sizeof info);
    for (uint8_t i = 0; i < info.count; ++i) {
      const float v = info.type == eelproto::SettingType::F32
                          ? info.min + (info.max - info.min) * (0.25f + 0.05f * i)
                          : (i % 2 == 0 ? info.max : info.min);
      bool changed = false;
      CHECK_EQ(eelproto::setting_set(s, info.key, i, v, changed), 0);
    }
  }
  return s;
}
}  // namespace

TEST(the_defaults_are_the_documented_ones_and_valid) {
  const eelproto::Settings s = eelproto::settings_defaults();
  CHECK_EQ(eelproto::settings_check(s), 0);
  CHECK_EQ(s.kp_nm_per_rad, eelproto::defaults<eelproto::SetGains>().kp_nm_per_rad);
  CHECK_EQ(s.offset_rate_rad_s, eelproto::defaults<eelproto::SetGait>().offset_rate_rad_s);
  CHECK_EQ(s.servo_us_per_rad, 636.6f);
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    CHECK_EQ(s.trim_us[j], 0);
    CHECK_EQ(s.adc_centre[j], 512);
  }
  CHECK_EQ(s.joint_feedback, 0);
  CHECK_EQ(s.battery_divider, 3.2f);  // the low-voltage stop armed by default
}

TEST(a_setting_reads_back_what_was_set_element_by_element) {
  eelproto::Settings s = eelproto::settings_defaults();
  bool changed = false;
  CHECK_EQ(eelproto::setting_set(s, key(SettingKey::TrimUs), 3, -125.0f, changed), 0);
  CHECK(changed);
  CHECK_EQ(s.trim_us[3], -125);
  CHECK_EQ(s.trim_us[2], 0);
  CHECK_EQ(eelproto::setting_set(s, key(SettingKey::AdcCountsPerRad), 4, 97.5f, changed), 0);
  CHECK_EQ(s.adc_counts_per_rad[4], 97.5f);
  CHECK_EQ(eelproto::setting_set(s, key(SettingKey::RadioId), 0, 65535.0f, changed), 0);
  CHECK_EQ(s.radio_id, 65535);
  float v = 0.0f;
  CHECK_EQ(eelproto::setting_get(s, key(SettingKey::TrimUs), 3, v), 0);
  CHECK_EQ(v, -125.0f);
  CHECK_EQ(eelproto::setting_get(s, key(SettingKey::AdcCountsPerRad), 4, v), 0);
  CHECK_EQ(v, 97.5f);
  CHECK_EQ(eelproto::setting_set(s, key(SettingKey::TrimUs), 3, -125.0f, changed), 0);
  CHECK(!changed);  // the same value again
}

TEST(a_bad_setting_is_refused_with_its_reason_and_changes_nothing) {
  using R = eelproto::RefuseReason;
  eelproto::Settings s = eelproto::settings_defaults();
  const eelproto::Settings before = s;
  bool changed = true;
  float v = 0.0f;
  CHECK_EQ(eelproto::setting_set(s, 0, 0, 1.0f, changed), why(R::UnknownSetting));
  CHECK_EQ(eelproto::setting_set(s, 200, 0, 1.0f, changed), why(R::UnknownSetting));
  CHECK_EQ(eelproto::setting_get(s, 200, 0, v), why(R::UnknownSetting));
  CHECK_EQ(eelproto::setting_set(s, key(SettingKey::TrimUs), cfg::kJoints, 1.0f, changed),
           why(R::OutOfRange));  // index past the joints
  CHECK_EQ(eelproto::setting_get(s, key(SettingKey::RadioId), 1, v), why(R::OutOfRange));
  CHECK_EQ(eelproto::setting_set(s, key(SettingKey::TrimUs), 0, 501.0f, changed),
           why(R::OutOfRange));
  CHECK_EQ(eelproto::setting_set(s, key(SettingKey::TrimUs), 0, 2.5f, changed),
           why(R::OutOfRange));  // an integer setting takes whole values
  CHECK_EQ(eelproto::setting_set(s, key(SettingKey::Reversed), 0, -1.0f, changed),
           why(R::OutOfRange));
  CHECK_EQ(eelproto::setting_set(s, key(SettingKey::KpNmPerRad), 0, NAN, changed),
           why(R::NotFinite));
  CHECK_EQ(eelproto::setting_set(s, key(SettingKey::BatteryLowV), 0, INFINITY, changed),
           why(R::NotFinite));
  CHECK(!changed);
  CHECK(same(s, before));
}

TEST(settings_round_trip_through_their_eeprom_image) {
  const eelproto::Settings s = all_changed();
  CHECK_EQ(eelproto::settings_check(s), 0);
  CHECK(!same(s, eelproto::settings_defaults()));
  uint8_t image[kSettingsImageBytes];
  settings_to_image(s, image);
  CHECK_EQ(wire::get_u16(image), eelproto::kSettingsVersion);
  eelproto::Settings back;
  CHECK(settings_from_image(image, back) == SettingsSource::Eeprom);
  CHECK(same(back, s));
}

TEST(a_blank_eeprom_boots_the_defaults_and_says_so) {
  const BlankImage blank;
  eelproto::Settings s = all_changed();
  CHECK(settings_from_image(blank.bytes, s) == SettingsSource::Blank);
  CHECK(same(s, eelproto::settings_defaults()));
}

TEST(any_flipped_bit_of_the_image_boots_the_defaults_as_corrupt_or_other_version) {
  uint8_t image[kSettingsImageBytes];
  settings_to_image(all_changed(), image);
  for (unsigned bit = 0; bit < 8 * sizeof image; ++bit) {
    image[bit / 8] ^= static_cast<uint8_t>(1U << (bit % 8));
    eelproto::Settings s;
    const SettingsSource source = settings_from_image(image, s);
    CHECK(source == (bit < 16 ? SettingsSource::OtherVersion : SettingsSource::Corrupt));
    CHECK(same(s, eelproto::settings_defaults()));
    image[bit / 8] ^= static_cast<uint8_t>(1U << (bit % 8));
  }
}

TEST(an_image_with_a_good_crc_but_a_value_out_of_range_boots_the_defaults) {
  eelproto::Settings bad = eelproto::settings_defaults();
  bad.trim_us[2] = 900;  // outside [-500, 500], as no SetSetting could have made it
  uint8_t image[kSettingsImageBytes];
  settings_to_image(bad, image);
  eelproto::Settings s;
  CHECK(settings_from_image(image, s) == SettingsSource::Corrupt);
  CHECK_EQ(s.trim_us[2], 0);
}
