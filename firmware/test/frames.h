// Helpers for tests that talk to the robot in frames.
#pragma once
#include <stdint.h>
#include <string.h>

#include "cobs.h"
#include "crc16.h"
#include "frame_codec.h"
#include "message_codec.h"
#include "wire.h"

struct Bytes {
  uint8_t data[256];
  size_t n = 0;
  void append(const uint8_t* p, size_t k) {
    memcpy(data + n, p, k);
    n += k;
  }
};

// A frame with arbitrary header fields and CRC, for making bad frames on purpose.
inline Bytes raw_frame(uint16_t schema, uint8_t id, uint8_t seq, const uint8_t* payload, size_t len,
                       bool corrupt_crc = false) {
  uint8_t body[300];
  wire::put_u16(body, schema);
  body[2] = id;
  body[3] = seq;
  if (len > 0) memcpy(body + 4, payload, len);  // memcpy from nullptr is undefined even for 0
  uint16_t crc = crc16_ccitt_false(body, 4 + len);
  if (corrupt_crc) crc ^= 0x0400;
  wire::put_u16(body + 4 + len, crc);
  Bytes out;
  out.n = cobs_encode(body, 6 + len, out.data, sizeof out.data - 1);
  out.data[out.n++] = 0;
  return out;
}

template <class M>
Bytes frame_of(const M& m, uint8_t seq) {
  uint8_t p[64];
  eelproto::pack(m, p);
  Bytes out;
  out.n = encode_frame(static_cast<uint8_t>(M::kId), seq, p, M::kPayloadBytes, out.data,
                       sizeof out.data);
  return out;
}
