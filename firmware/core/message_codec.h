// The one codec of every message: pack, unpack, validate and defaults walk a message's field
// table (its each_field() in protocol_gen.h, generated from protocol/eelbot.toml) and encode or
// decode each field with the wire:: function for its type, or copy a whole struct that has no
// padding (every message on the AVR).
#pragma once
#include <stdint.h>
#include <string.h>

#include "protocol_gen.h"
#include "wire.h"

namespace eelproto {
namespace codec {

struct Packer {
  uint8_t* p;
  template <typename T>
  void operator()(const T& v, uint8_t offset) { wire::put(p + offset, v); }
  void operator()(float v, uint8_t offset, float /*min*/, float /*max*/, float /*default*/) {
    wire::put(p + offset, v);
  }
};

struct Unpacker {
  const uint8_t* p;
  template <typename T>
  void operator()(T& v, uint8_t offset) { wire::get(p + offset, v); }
  void operator()(float& v, uint8_t offset, float /*min*/, float /*max*/, float /*default*/) {
    wire::get(p + offset, v);
  }
};

// The RefuseReason of the worst field: NotFinite anywhere wins over OutOfRange anywhere.
struct RangeCheck {
  uint8_t reason;
  template <typename T>
  void operator()(const T& /*v*/, uint8_t /*offset*/) {}
  void operator()(float v, uint8_t /*offset*/, float min, float max, float /*default*/) {
    if (!wire::finite(v)) {
      reason = static_cast<uint8_t>(RefuseReason::NotFinite);
    } else if (reason == 0 && (v < min || v > max)) {
      reason = static_cast<uint8_t>(RefuseReason::OutOfRange);
    }
  }
};

struct Defaults {
  template <typename T>
  void operator()(T& /*v*/, uint8_t /*offset*/) {}
  void operator()(float& v, uint8_t /*offset*/, float /*min*/, float /*max*/, float value) {
    v = value;
  }
};

}  // namespace codec

// A struct without padding holds its fields exactly as the payload does (the generator declares
// them in wire order, the wire is little-endian as the machine is): then packing is one copy. So
// it is for every message on the AVR (alignment 1), which keeps the codec's flash small there; on
// a PC most structs have padding and go field by field.
template <typename M>
constexpr bool is_wire_image() {
  return sizeof(M) == M::kPayloadBytes && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__;
}

// Payload bytes of a message (M::kPayloadBytes of them).
template <typename M>
inline void pack(const M& m, uint8_t* p) {
  if (is_wire_image<M>()) {
    memcpy(p, &m, M::kPayloadBytes);
    return;
  }
  codec::Packer visit{p};
  each_field(const_cast<M&>(m), visit);  // the packer only reads: one field table serves both ways
}

template <typename M>
inline void unpack(M& m, const uint8_t* p) {
  if (is_wire_image<M>()) {
    memcpy(&m, p, M::kPayloadBytes);
    return;
  }
  codec::Unpacker visit{p};
  each_field(m, visit);
}

// RefuseReason value, or 0 when every field with a range is finite and in range.
template <typename M>
inline uint8_t validate(const M& m) {
  codec::RangeCheck visit{0};
  each_field(const_cast<M&>(m), visit);
  return visit.reason;
}

// A command with every field at its documented default (the firmware's boot values); fields
// without a default (those of messages the robot sends) are 0.
template <typename M>
inline M defaults() {
  M m{};
  codec::Defaults visit;
  each_field(m, visit);
  return m;
}

}  // namespace eelproto
