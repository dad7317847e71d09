// libFuzzer target for the generic codecs: messages (core/message_codec.h) and settings
// (core/settings_codec.h). The first byte picks what to decode, the rest is its input.
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "message_codec.h"
#include "settings_codec.h"
#include "wire.h"

namespace {
void require(bool ok) {
  if (!ok) __builtin_trap();
}

// Any payload of the right size unpacks into a message that packs back to the same bytes (floats
// travel as bits, NaNs included), and validate gives a RefuseReason or 0.
template <typename M>
void round_trip(const uint8_t* p, size_t n) {
  if (n < M::kPayloadBytes) return;
  M m{};
  eelproto::unpack(m, p);
  uint8_t back[M::kPayloadBytes + 1];
  eelproto::pack(m, back);
  require(memcmp(back, p, M::kPayloadBytes) == 0);
  require(eelproto::validate(m) <= static_cast<uint8_t>(eelproto::RefuseReason::NotFinite));
  require(eelproto::validate(eelproto::defaults<M>()) == 0);
}

// SetSetting's key, index and value: accepted, it reads back as set; refused, nothing changed.
void set_setting(const uint8_t* p, size_t n) {
  if (n < 6) return;
  eelproto::Settings s = eelproto::settings_defaults();
  uint8_t before[eelproto::kSettingsBytes], after[eelproto::kSettingsBytes];
  eelproto::settings_pack(s, before);
  const float value = wire::get_f32(p + 2);
  bool changed = false;
  const uint8_t why = eelproto::setting_set(s, p[0], p[1], value, changed);
  eelproto::settings_pack(s, after);
  require(eelproto::settings_check(s) == 0);
  if (why != 0) {
    require(!changed && memcmp(before, after, sizeof before) == 0);
    return;
  }
  float got = 0.0f;
  require(eelproto::setting_get(s, p[0], p[1], got) == 0);
  require(got == value);
  // `changed` is about the value: storing -0 over 0 changes bits, not the value.
  if (changed) require(memcmp(before, after, sizeof before) != 0);
  if (memcmp(before, after, sizeof before) != 0 && !changed) require(value == 0.0f);
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const uint8_t* p = data + 1;
  const size_t n = size - 1;
  switch (data[0] % 17) {
    case 0: round_trip<eelproto::SetGait>(p, n); break;
    case 1: round_trip<eelproto::SetOffset>(p, n); break;
    case 2: round_trip<eelproto::SetGains>(p, n); break;
    case 3: round_trip<eelproto::GetSetting>(p, n); break;
    case 4: round_trip<eelproto::SetSetting>(p, n); break;
    case 5: round_trip<eelproto::Version>(p, n); break;
    case 6: round_trip<eelproto::Telemetry>(p, n); break;
    case 7: round_trip<eelproto::Ack>(p, n); break;
    case 8: round_trip<eelproto::Refuse>(p, n); break;
    case 9: round_trip<eelproto::Setting>(p, n); break;
    case 10: round_trip<eelproto::Status>(p, n); break;
    default: set_setting(p, n); break;
  }
  return 0;
}
