#include "frame_codec.h"

#include "crc16.h"
#include "crc32.h"
#include "wire.h"

namespace {
// Bytes after the part a CRC covers: the CRC-16 covers all but itself, the CRC-32 all but both.
constexpr uint8_t kCrc16Lag = eelproto::kCrcBytes;
constexpr uint8_t kCrc32Lag = eelproto::kCrcBytes + eelproto::kCommandCrcBytes;

uint8_t check_bytes(uint8_t msg_id) {
  return eelproto::is_to_robot(msg_id) ? eelproto::kCommandCrcBytes : 0;
}
}  // namespace

void FrameDecoder::clear() {
  len_ = 0;
  encoded_ = 0;
  overflow_ = false;
  cobs_.clear();
  crc16_not_ = 0;
  crc32_not_ = 0;
}

// Each decoded byte enters the CRCs once the bytes after it show that it is not part of a CRC
// field: byte i enters the CRC-16 when byte i + 2 arrives, the CRC-32 when byte i + 6 arrives.
void FrameDecoder::emit(uint8_t byte) {
  buf_[len_++] = byte;
  if (len_ > kCrc16Lag) {
    const uint16_t reg = crc16_ccitt_false_step(crc16_not_ ^ kCrc16Init, buf_[len_ - 1 - kCrc16Lag]);
    crc16_not_ = reg ^ kCrc16Init;
  }
  if (len_ > kCrc32Lag) crc32_not_ = ~crc32_iso_hdlc_step(~crc32_not_, buf_[len_ - 1 - kCrc32Lag]);
}

bool FrameDecoder::push(uint8_t byte, LinkCounters& counters) {
  if (byte != 0) {
    if (overflow_) return false;
    if (encoded_ == frame::kMaxEncoded) {
      overflow_ = true;  // counted now, once, even if the delimiter never comes
      ++counters.bad_oversize;
      return false;
    }
    ++encoded_;
    uint8_t decoded;
    if (cobs_.push(byte, decoded)) emit(decoded);
    return false;
  }
  const bool any = encoded_ > 0 && !overflow_;  // back-to-back delimiters are padding, not frames
  const bool ok = any && finish(counters);
  clear();
  return ok;
}

bool FrameDecoder::finish(LinkCounters& counters) {
  const uint8_t n = len_;
  if (!cobs_.complete()) {
    ++counters.bad_cobs;
    return false;
  }
  if (n < frame::kOverhead) {
    ++counters.bad_short;
    return false;
  }
  const uint16_t crc16 = crc16_not_ ^ kCrc16Init;
  if (crc16 != wire::get_u16(buf_ + n - eelproto::kCrcBytes)) {
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
  const uint8_t check = check_bytes(id);
  if (n != frame::kOverhead + want + check) {
    ++counters.bad_length;
    return false;
  }
  frame_.check = crc16;
  if (check != 0) {
    frame_.check = crc32_not_;  // the complemented register is the CRC-32
    if (frame_.check != wire::get_u32(buf_ + n - kCrc32Lag)) {
      ++counters.bad_crc32;
      return false;
    }
  }
  frame_.msg_id = id;
  frame_.seq = buf_[3];
  frame_.payload_len = static_cast<uint8_t>(want);
  frame_.payload = buf_ + eelproto::kHeaderBytes;
  return true;
}

size_t encode_frame(uint8_t msg_id, uint8_t seq, const uint8_t* payload, uint8_t payload_len,
                    uint8_t* out, size_t cap) {
  const uint8_t check = check_bytes(msg_id);
  if (payload_len > frame::kMaxPayload - check) return 0;
  uint8_t raw[frame::kMaxDecoded];
  wire::put_u16(raw, eelproto::kSchemaHash);
  raw[2] = msg_id;
  raw[3] = seq;
  for (uint8_t i = 0; i < payload_len; ++i) raw[eelproto::kHeaderBytes + i] = payload[i];
  uint8_t body = static_cast<uint8_t>(eelproto::kHeaderBytes + payload_len);
  if (check != 0) {
    wire::put_u32(raw + body, crc32_iso_hdlc(raw, body));
    body = static_cast<uint8_t>(body + check);
  }
  wire::put_u16(raw + body, crc16_ccitt_false(raw, body));
  if (cap < 1) return 0;
  const size_t n = cobs_encode(raw, body + eelproto::kCrcBytes, out, cap - 1);
  if (n == 0) return 0;
  out[n] = 0;
  return n + 1;
}
