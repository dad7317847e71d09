// The generic codec (core/message_codec.h) over the generated field tables (core/protocol_gen.h).
#include <math.h>

#include "check.h"
#include "message_codec.h"

TEST(mixed_width_fields_are_packed_little_endian_at_their_offsets) {
  const eelproto::Version v{0, 1, 2, eelproto::kNJoints, 0xBEEF, 0x01020304UL};
  uint8_t p[eelproto::Version::kPayloadBytes];
  eelproto::pack(v, p);
  const uint8_t want[] = {0, 1, 2, eelproto::kNJoints, 0xEF, 0xBE, 0x04, 0x03, 0x02, 0x01};
  static_assert(sizeof(want) == sizeof(p), "Version's layout changed: update this test");
  for (uint8_t i = 0; i < sizeof(p); ++i) CHECK_EQ(p[i], want[i]);
}

TEST(every_field_of_a_message_with_an_array_round_trips) {
  eelproto::Telemetry t{};
  t.time_us = 0xFFFFFFF0UL;
  t.state = 2;
  for (uint8_t j = 0; j < eelproto::kNJoints; ++j) t.alpha_rad[j] = -0.5f + 0.125f * j;
  t.offset_rad = 0.25f;
  t.amplitude_rad = 1.5f;
  t.frames_ok = 65535;
  t.frames_bad = 7;
  t.frames_lost = 300;
  uint8_t p[eelproto::Telemetry::kPayloadBytes];
  eelproto::pack(t, p);
  eelproto::Telemetry u{};
  eelproto::unpack(u, p);
  CHECK_EQ(u.time_us, t.time_us);
  CHECK_EQ(u.state, t.state);
  for (uint8_t j = 0; j < eelproto::kNJoints; ++j) CHECK_EQ(u.alpha_rad[j], t.alpha_rad[j]);
  CHECK_EQ(u.offset_rad, t.offset_rad);
  CHECK_EQ(u.amplitude_rad, t.amplitude_rad);
  CHECK_EQ(u.frames_ok, t.frames_ok);
  CHECK_EQ(u.frames_bad, t.frames_bad);
  CHECK_EQ(u.frames_lost, t.frames_lost);
}

TEST(the_documented_defaults_are_valid_commands) {
  CHECK_EQ(eelproto::validate(eelproto::defaults<eelproto::SetGait>()), 0);
  CHECK_EQ(eelproto::validate(eelproto::defaults<eelproto::SetOffset>()), 0);
  CHECK_EQ(eelproto::validate(eelproto::defaults<eelproto::SetGains>()), 0);
  CHECK(eelproto::defaults<eelproto::SetGait>().omega_rad_s > 0.0f);  // not left at 0
}

TEST(a_non_finite_field_outranks_an_out_of_range_field_before_it) {
  const uint8_t not_finite = static_cast<uint8_t>(eelproto::RefuseReason::NotFinite);
  const uint8_t out_of_range = static_cast<uint8_t>(eelproto::RefuseReason::OutOfRange);
  eelproto::SetGait g = eelproto::defaults<eelproto::SetGait>();
  g.amplitude_rad = 99.0f;  // first field: out of range
  CHECK_EQ(eelproto::validate(g), out_of_range);
  g.offset_rate_rad_s = NAN;  // last field: not finite
  CHECK_EQ(eelproto::validate(g), not_finite);
  g.amplitude_rad = 0.5f;
  g.offset_rate_rad_s = INFINITY;
  CHECK_EQ(eelproto::validate(g), not_finite);
  g.offset_rate_rad_s = -0.001f;  // just below its minimum of 0
  CHECK_EQ(eelproto::validate(g), out_of_range);
}
