// The generic codec (core/message_codec.h) over the generated field tables (core/protocol_gen.h).
#include <math.h>

#include "check.h"
#include "message_codec.h"

TEST(mixed_width_fields_are_packed_little_endian_at_their_offsets) {
  const eelproto::Version v{0, 1, 2, eelproto::kNJoints, 0xBEEF, 0x01020304UL, 0x1234, 0xA0B0};
  uint8_t p[eelproto::Version::kPayloadBytes];
  eelproto::pack(v, p);
  const uint8_t want[] = {0,    1,    2,    eelproto::kNJoints, 0xEF, 0xBE, 0x04,
                          0x03, 0x02, 0x01, 0x34,               0x12, 0xB0, 0xA0};
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
  for (uint8_t j = 0; j < eelproto::kNJoints; ++j) t.phi_mrad[j] = static_cast<int16_t>(-1200 + 500 * j);
  t.flags = 0x15;
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
  CHECK_EQ(u.flags, t.flags);
  for (uint8_t j = 0; j < eelproto::kNJoints; ++j) CHECK_EQ(u.phi_mrad[j], t.phi_mrad[j]);
  // The negative i16 travels as two's complement, little-endian, after everything else.
  CHECK_EQ(p[eelproto::Telemetry::kPayloadBytes - 2 * eelproto::kNJoints], 0x50);
  CHECK_EQ(p[eelproto::Telemetry::kPayloadBytes - 2 * eelproto::kNJoints + 1], 0xFB);
}

TEST(a_struct_without_padding_packs_exactly_as_field_by_field) {
  // Ack (two u8) has no padding anywhere: packed by one copy. Status has padding on a PC: packed
  // field by field. Both give the documented layout.
  static_assert(eelproto::is_wire_image<eelproto::Ack>(), "Ack has no padding");
  const eelproto::Ack a{0x83, 0x07};
  uint8_t p[2];
  eelproto::pack(a, p);
  CHECK_EQ(p[0], 0x83);
  CHECK_EQ(p[1], 0x07);
  eelproto::Status s{};
  s.time_us = 0x11223344UL;
  s.resets = 0x5566;
  s.battery_v = 7.25f;
  s.tx_dropped = 0xA1B2;
  uint8_t q[eelproto::Status::kPayloadBytes];
  eelproto::pack(s, q);
  CHECK_EQ(wire::get_u32(q), 0x11223344UL);
  CHECK_EQ(wire::get_u16(q + 7), 0x5566);
  CHECK_EQ(wire::get_f32(q + 10), 7.25f);
  CHECK_EQ(wire::get_u16(q + eelproto::Status::kPayloadBytes - 2), 0xA1B2);
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
