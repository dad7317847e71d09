#include "check.h"
#include "frames.h"

namespace {
struct Fed {
  int frames = 0;
  Frame last{};
};

Fed feed(FrameDecoder& d, LinkCounters& c, const Bytes& b) {
  Fed r;
  for (size_t i = 0; i < b.n; ++i) {
    if (d.push(b.data[i], c)) {
      ++r.frames;
      r.last = d.frame();
    }
  }
  return r;
}

eelproto::SetOffset offset_msg(float v) {
  eelproto::SetOffset m;
  m.offset_rad = v;
  return m;
}
}  // namespace

TEST(frame_round_trips_through_encoder_and_decoder) {
  FrameDecoder d;
  LinkCounters c{};
  const Fed r = feed(d, c, frame_of(offset_msg(0.25f), 7));
  CHECK_EQ(r.frames, 1);
  CHECK_EQ(r.last.msg_id, static_cast<uint8_t>(eelproto::MsgId::SetOffset));
  CHECK_EQ(r.last.seq, 7);
  CHECK_EQ(r.last.payload_len, 4);
  CHECK_EQ(wire::get_f32(r.last.payload), 0.25f);
  CHECK_EQ(c.bad_total(), 0);
}

TEST(largest_message_fits_the_radio_frame_budget) {
  eelproto::Telemetry t{};
  const Bytes b = frame_of(t, 0);
  CHECK(b.n > 0 && b.n <= eelproto::kMaxFrameBytes);
}

TEST(garbage_frame_is_counted_as_cobs_error_and_ignored) {
  FrameDecoder d;
  LinkCounters c{};
  Bytes b;
  const uint8_t junk[] = {0x09, 0x11, 0x22, 0x00};  // block runs past the end
  b.append(junk, sizeof junk);
  CHECK_EQ(feed(d, c, b).frames, 0);
  CHECK_EQ(c.bad_cobs, 1);
  CHECK_EQ(c.bad_total(), 1);
}

TEST(truncated_frame_is_counted_as_short_and_ignored) {
  FrameDecoder d;
  LinkCounters c{};
  Bytes b;
  const uint8_t tiny[] = {0x04, 0x84, 0x8D, 0x02, 0x00};  // 3 bytes: less than header + CRC
  b.append(tiny, sizeof tiny);
  CHECK_EQ(feed(d, c, b).frames, 0);
  CHECK_EQ(c.bad_short, 1);
  CHECK_EQ(c.bad_total(), 1);
}

TEST(oversize_frame_is_counted_once_and_the_next_frame_still_decodes) {
  FrameDecoder d;
  LinkCounters c{};
  Bytes b;
  uint8_t lots[200];
  memset(lots, 0x55, sizeof lots);
  b.append(lots, sizeof lots);
  b.append(lots, 1);
  const uint8_t zero = 0;
  b.append(&zero, 1);
  const Bytes good = frame_of(offset_msg(0.1f), 1);
  b.append(good.data, good.n);
  CHECK_EQ(feed(d, c, b).frames, 1);
  CHECK_EQ(c.bad_oversize, 1);
  CHECK_EQ(c.bad_total(), 1);
}

TEST(wrong_crc_frame_is_counted_and_ignored) {
  FrameDecoder d;
  LinkCounters c{};
  uint8_t p[4] = {0, 0, 0x80, 0x3E};
  CHECK_EQ(feed(d, c, raw_frame(eelproto::kSchemaHash, 0x03, 0, p, 4, Spoil::Crc16)).frames, 0);
  CHECK_EQ(c.bad_crc, 1);
  CHECK_EQ(c.bad_total(), 1);
}

TEST(wrong_schema_frame_is_counted_and_ignored) {
  FrameDecoder d;
  LinkCounters c{};
  uint8_t p[4] = {0, 0, 0x80, 0x3E};
  const uint16_t other = static_cast<uint16_t>(eelproto::kSchemaHash ^ 0x0101);
  CHECK_EQ(feed(d, c, raw_frame(other, 0x03, 0, p, 4)).frames, 0);
  CHECK_EQ(c.bad_schema, 1);
  CHECK_EQ(c.bad_total(), 1);
}

TEST(unknown_message_id_is_counted_and_ignored) {
  FrameDecoder d;
  LinkCounters c{};
  CHECK_EQ(feed(d, c, raw_frame(eelproto::kSchemaHash, 0x7E, 0, nullptr, 0)).frames, 0);
  CHECK_EQ(c.bad_unknown_id, 1);
  CHECK_EQ(c.bad_total(), 1);
}

TEST(payload_of_the_wrong_length_is_counted_and_ignored) {
  FrameDecoder d;
  LinkCounters c{};
  uint8_t p[3] = {1, 2, 3};  // SetOffset needs 4
  CHECK_EQ(feed(d, c, raw_frame(eelproto::kSchemaHash, 0x03, 0, p, 3)).frames, 0);
  CHECK_EQ(c.bad_length, 1);
  CHECK_EQ(c.bad_total(), 1);
}

TEST(decoder_resynchronises_at_the_delimiter_after_garbage) {
  FrameDecoder d;
  LinkCounters c{};
  Bytes b;
  const uint8_t noise[] = {0x13, 0x37, 0xFE, 0x01};  // no delimiter: glued to the next frame
  b.append(noise, sizeof noise);
  const Bytes lost = frame_of(offset_msg(0.1f), 1);  // destroyed by the glued noise
  b.append(lost.data, lost.n);
  const Bytes good = frame_of(offset_msg(0.2f), 2);
  b.append(good.data, good.n);
  const Fed r = feed(d, c, b);
  CHECK_EQ(r.frames, 1);
  CHECK_EQ(r.last.seq, 2);
  CHECK_EQ(c.bad_total(), 1);
}

TEST(empty_frames_between_delimiters_are_padding_not_errors) {
  FrameDecoder d;
  LinkCounters c{};
  Bytes b;
  const uint8_t zeros[] = {0, 0, 0};
  b.append(zeros, sizeof zeros);
  CHECK_EQ(feed(d, c, b).frames, 0);
  CHECK_EQ(c.bad_total(), 0);
}

TEST(encoder_refuses_a_payload_too_large_for_a_frame) {
  uint8_t p[frame::kMaxPayload + 1] = {};
  uint8_t out[128];
  CHECK_EQ(encode_frame(0x03, 0, p, sizeof p, out, sizeof out), 0u);
  CHECK(encode_frame(0x03, 0, p, frame::kMaxPayload, out, sizeof out) <= eelproto::kMaxFrameBytes);
}

TEST(a_command_whose_crc32_fails_is_counted_and_ignored_though_its_crc16_holds) {
  FrameDecoder d;
  LinkCounters c{};
  uint8_t p[4] = {0, 0, 0x80, 0x3E};
  CHECK_EQ(feed(d, c, raw_frame(eelproto::kSchemaHash, 0x03, 0, p, 4, Spoil::Crc32)).frames, 0);
  CHECK_EQ(c.bad_crc32, 1);
  CHECK_EQ(c.bad_total(), 1);
}

TEST(a_command_without_its_crc32_has_the_wrong_length) {
  FrameDecoder d;
  LinkCounters c{};
  uint8_t p[4] = {0, 0, 0x80, 0x3E};
  CHECK_EQ(feed(d, c, raw_frame(eelproto::kSchemaHash, 0x03, 0, p, 4, Spoil::NoCrc32)).frames, 0);
  CHECK_EQ(c.bad_length, 1);
}

TEST(frames_to_the_host_carry_no_crc32_and_decode_too) {
  FrameDecoder d;
  LinkCounters c{};
  const eelproto::Ack a{3, 9};
  const Bytes b = frame_of(a, 4);
  CHECK_EQ(b.n, 10u);  // COBS(4 + 2 + 2) + delimiter
  const Fed r = feed(d, c, b);
  CHECK_EQ(r.frames, 1);
  CHECK_EQ(r.last.msg_id, static_cast<uint8_t>(eelproto::MsgId::Ack));
  CHECK_EQ(c.bad_total(), 0);
}

TEST(the_frame_check_is_the_crc32_of_a_command_so_a_repeat_has_the_same) {
  FrameDecoder d;
  LinkCounters c{};
  const Fed a = feed(d, c, frame_of(offset_msg(0.25f), 7));
  const Fed b = feed(d, c, frame_of(offset_msg(0.25f), 7));
  const Fed other = feed(d, c, frame_of(offset_msg(0.5f), 7));
  CHECK_EQ(a.last.check, b.last.check);
  CHECK(a.last.check != other.last.check);
  uint8_t body[8];
  wire::put_u16(body, eelproto::kSchemaHash);
  body[2] = 0x03;
  body[3] = 7;
  wire::put_f32(body + 4, 0.25f);
  CHECK_EQ(a.last.check, crc32_iso_hdlc(body, sizeof body));
}

TEST(the_decoder_finds_a_frame_after_every_split_of_a_garbled_stream) {
  // Whatever garbage ends at a delimiter, the next frame decodes: the decoder keeps no state
  // across a delimiter.
  const Bytes good = frame_of(offset_msg(0.3f), 5);
  for (uint8_t junk_len = 0; junk_len < 70; ++junk_len) {
    FrameDecoder d;
    LinkCounters c{};
    Bytes b;
    for (uint8_t i = 0; i < junk_len; ++i) {
      const uint8_t x = static_cast<uint8_t>(1 + (i * 37) % 255);
      b.append(&x, 1);
    }
    const uint8_t zero = 0;
    b.append(&zero, 1);
    b.append(good.data, good.n);
    const Fed r = feed(d, c, b);
    CHECK_EQ(r.frames, 1);
    CHECK_EQ(r.last.seq, 5);
  }
}
