#include "frame_codec.h"

#include "cobs.h"
#include "crc16.h"
#include "wire.h"

bool FrameDecoder::push(uint8_t byte, LinkCounters& counters) {
  if (byte != 0) {
    if (overflow_) return false;
    if (len_ == sizeof(buf_)) {
      overflow_ = true;  // counted now, once, even if the delimiter never comes
      ++counters.bad_oversize;
      return false;
    }
    buf_[len_++] = byte;
    return false;
  }
  if (overflow_) {
    overflow_ = false;
    len_ = 0;
    return false;
  }
  if (len_ == 0) return false;  // back-to-back delimiters are legal padding, not frames
  const bool ok = finish(counters);
  len_ = 0;
  return ok;
}

bool FrameDecoder::finish(LinkCounters& counters) {
  const int n = cobs_decode(buf_, len_, buf_, sizeof(buf_));
  if (n < 0) {
    ++counters.bad_cobs;
    return false;
  }
  if (n < frame::kOverhead) {
    ++counters.bad_short;
    return false;
  }
  const uint8_t body = static_cast<uint8_t>(n - eelproto::kCrcBytes);
  if (crc16_ccitt_false(buf_, body) != wire::get_u16(buf_ + body)) {
    ++counters.bad_crc;
    return false;
  }
  if (wire::get_u16(buf_) != eelproto::kSchemaHash) {
    ++counters.bad_schema;
    return false;
  }
  const uint8_t id = buf_[2];
  const int16_t want = eelproto::payload_bytes(id);
  if (want < 0) {
    ++counters.bad_unknown_id;
    return false;
  }
  if (want != body - eelproto::kHeaderBytes) {
    ++counters.bad_length;
    return false;
  }
  frame_.msg_id = id;
  frame_.seq = buf_[3];
  frame_.payload_len = static_cast<uint8_t>(want);
  frame_.payload = buf_ + eelproto::kHeaderBytes;
  return true;
}

size_t encode_frame(uint8_t msg_id, uint8_t seq, const uint8_t* payload, uint8_t payload_len,
                    uint8_t* out, size_t cap) {
  if (payload_len > frame::kMaxPayload) return 0;
  uint8_t raw[frame::kMaxPayload + frame::kOverhead];
  wire::put_u16(raw, eelproto::kSchemaHash);
  raw[2] = msg_id;
  raw[3] = seq;
  for (uint8_t i = 0; i < payload_len; ++i) raw[eelproto::kHeaderBytes + i] = payload[i];
  const uint8_t body = static_cast<uint8_t>(eelproto::kHeaderBytes + payload_len);
  wire::put_u16(raw + body, crc16_ccitt_false(raw, body));
  if (cap < 1) return 0;
  const size_t n = cobs_encode(raw, body + eelproto::kCrcBytes, out, cap - 1);
  if (n == 0) return 0;
  out[n] = 0;
  return n + 1;
}
