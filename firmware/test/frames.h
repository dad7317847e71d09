// Helpers for tests that talk to the robot in frames.
#pragma once
#include <stdint.h>
#include <string.h>

#include "cobs.h"
#include "crc16.h"
#include "crc32.h"
#include "frame_codec.h"
#include "message_codec.h"
#include "settings_store.h"
#include "wire.h"

struct Bytes {
  uint8_t data[256];
  size_t n = 0;
  void append(const uint8_t* p, size_t k) {
    memcpy(data + n, p, k);
    n += k;
  }
};

// What to get wrong on purpose in raw_frame().
enum class Spoil { None, Crc16, Crc32, NoCrc32 };

// A frame with arbitrary header fields and CRCs, for making bad frames on purpose. Messages to the
// robot carry the CRC-32 unless spoiled.
inline Bytes raw_frame(uint16_t schema, uint8_t id, uint8_t seq, const uint8_t* payload, size_t len,
                       Spoil spoil = Spoil::None) {
  uint8_t body[300];
  wire::put_u16(body, schema);
  body[2] = id;
  body[3] = seq;
  if (len > 0) memcpy(body + 4, payload, len);  // memcpy from nullptr is undefined even for 0
  size_t n = 4 + len;
  if (eelproto::is_to_robot(id) && spoil != Spoil::NoCrc32) {
    uint32_t crc32 = crc32_iso_hdlc(body, n);
    if (spoil == Spoil::Crc32) crc32 ^= 0x00100000UL;
    wire::put_u32(body + n, crc32);
    n += 4;
  }
  uint16_t crc = crc16_ccitt_false(body, n);
  if (spoil == Spoil::Crc16) crc ^= 0x0400;
  wire::put_u16(body + n, crc);
  Bytes out;
  out.n = cobs_encode(body, n + 2, out.data, sizeof out.data - 1);
  out.data[out.n++] = 0;
  return out;
}

template <class M>
Bytes frame_of(const M& m, uint8_t seq) {
  uint8_t p[64] = {};
  eelproto::pack(m, p);
  Bytes out;
  out.n = encode_frame(static_cast<uint8_t>(M::kId), seq, p, M::kPayloadBytes, out.data,
                       sizeof out.data);
  return out;
}

// An erased EEPROM's settings image.
struct BlankImage {
  uint8_t bytes[kSettingsImageBytes];
  BlankImage() { memset(bytes, 0xFF, sizeof bytes); }
};
