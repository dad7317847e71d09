#include "settings_codec.h"

#include <string.h>

#include "flash_table.h"
#include "wire.h"

namespace eelproto {
namespace {

constexpr uint8_t kOutOfRange = static_cast<uint8_t>(RefuseReason::OutOfRange);
constexpr uint8_t kNotFinite = static_cast<uint8_t>(RefuseReason::NotFinite);

uint8_t type_bytes(SettingType t) {
  return t == SettingType::U8 ? 1 : (t == SettingType::F32 ? 4 : 2);
}

SettingInfo row(uint8_t i) {
  SettingInfo info;
  flash_read(&info, &kSettingTable[i], sizeof info);
  return info;
}

// The row of a key; false for a key this firmware does not have.
bool find(uint8_t key, SettingInfo& info) {
  for (uint8_t i = 0; i < kSettingCount; ++i) {
    info = row(i);
    if (info.key == key) return true;
  }
  return false;
}

// Element i of a setting in the struct: its bytes, in the machine's own representation.
uint8_t* at(Settings& s, const SettingInfo& info, uint8_t i) {
  return reinterpret_cast<uint8_t*>(&s) + info.offset + i * type_bytes(info.type);
}

float load(const Settings& s, const SettingInfo& info, uint8_t i) {
  const uint8_t* p = at(const_cast<Settings&>(s), info, i);
  switch (info.type) {
    case SettingType::U8:
      return *p;
    case SettingType::U16: {
      uint16_t v;
      memcpy(&v, p, 2);
      return static_cast<float>(v);
    }
    case SettingType::I16: {
      int16_t v;
      memcpy(&v, p, 2);
      return static_cast<float>(v);
    }
    default: {
      float v;
      memcpy(&v, p, 4);
      return v;
    }
  }
}

// Store a value that why_not() accepted (so the conversion to an integer type is exact).
void store(Settings& s, const SettingInfo& info, uint8_t i, float value) {
  uint8_t* p = at(s, info, i);
  switch (info.type) {
    case SettingType::U8:
      *p = static_cast<uint8_t>(value);
      break;
    case SettingType::U16: {
      const uint16_t v = static_cast<uint16_t>(value);
      memcpy(p, &v, 2);
      break;
    }
    case SettingType::I16: {
      const int16_t v = static_cast<int16_t>(value);
      memcpy(p, &v, 2);
      break;
    }
    default:
      memcpy(p, &value, 4);
  }
}

// Why a value cannot be element of this setting (0 when it can): not finite, outside the range,
// or not whole for an integer setting (the range lies inside the type's, so a whole value in
// range converts exactly).
uint8_t why_not(const SettingInfo& info, float v) {
  if (!wire::finite(v)) return kNotFinite;
  if (v < info.min || v > info.max) return kOutOfRange;
  if (info.type != SettingType::F32 && static_cast<float>(static_cast<int32_t>(v)) != v) {
    return kOutOfRange;
  }
  return 0;
}

}  // namespace

uint8_t setting_get(const Settings& s, uint8_t key, uint8_t index, float& value) {
  SettingInfo info;
  if (!find(key, info)) return static_cast<uint8_t>(RefuseReason::UnknownSetting);
  if (index >= info.count) return kOutOfRange;
  value = load(s, info, index);
  return 0;
}

uint8_t setting_set(Settings& s, uint8_t key, uint8_t index, float value, bool& changed) {
  SettingInfo info;
  changed = false;
  if (!find(key, info)) return static_cast<uint8_t>(RefuseReason::UnknownSetting);
  if (index >= info.count) return kOutOfRange;
  const uint8_t why = why_not(info, value);
  if (why != 0) return why;
  changed = load(s, info, index) != value;
  store(s, info, index, value);
  return 0;
}

Settings settings_defaults() {
  Settings s;
  for (uint8_t r = 0; r < kSettingCount; ++r) {
    const SettingInfo info = row(r);
    for (uint8_t i = 0; i < info.count; ++i) store(s, info, i, info.default_value);
  }
  return s;
}

uint8_t settings_check(const Settings& s) {
  for (uint8_t r = 0; r < kSettingCount; ++r) {
    const SettingInfo info = row(r);
    for (uint8_t i = 0; i < info.count; ++i) {
      const uint8_t why = why_not(info, load(s, info, i));
      if (why != 0) return why;
    }
  }
  return 0;
}

// The image holds each element little-endian, as the struct does on every machine this firmware
// builds for (the AVR and the PCs of the native build): a copy, element by element without the
// struct's padding.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the settings image is little-endian");

void settings_pack(const Settings& s, uint8_t* p) {
  for (uint8_t r = 0; r < kSettingCount; ++r) {
    const SettingInfo info = row(r);
    const uint8_t n = static_cast<uint8_t>(info.count * type_bytes(info.type));
    memcpy(p, at(const_cast<Settings&>(s), info, 0), n);
    p += n;
  }
}

void settings_unpack(Settings& s, const uint8_t* p) {
  for (uint8_t r = 0; r < kSettingCount; ++r) {
    const SettingInfo info = row(r);
    const uint8_t n = static_cast<uint8_t>(info.count * type_bytes(info.type));
    memcpy(at(s, info, 0), p, n);
    p += n;
  }
}

}  // namespace eelproto
