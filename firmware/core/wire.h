// Little-endian field access for the wire format. Through memcpy or byte by byte on purpose: the
// frame buffer has no alignment guarantee, and the result must not depend on the host's
// endianness (on a little-endian machine, the AVR's and the PC's, the copy is the byte order).
#pragma once
#include <stdint.h>
#include <string.h>

namespace wire {

inline void put_u8(uint8_t* p, uint8_t v) { p[0] = v; }
inline void put_u16(uint8_t* p, uint16_t v) {
  p[0] = static_cast<uint8_t>(v);
  p[1] = static_cast<uint8_t>(v >> 8);
}
inline void put_u32(uint8_t* p, uint32_t v) {
#if __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
  memcpy(p, &v, 4);
#else
  for (uint8_t i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
#endif
}
inline void put_f32(uint8_t* p, float v) {
  static_assert(sizeof(float) == 4, "the wire carries IEEE-754 binary32");
  uint32_t bits;
  memcpy(&bits, &v, 4);  // memcpy, not a cast: no strict-aliasing trouble
  put_u32(p, bits);
}

inline uint8_t get_u8(const uint8_t* p) { return p[0]; }
inline uint16_t get_u16(const uint8_t* p) {
  return static_cast<uint16_t>(p[0] | (static_cast<uint16_t>(p[1]) << 8));
}
inline uint32_t get_u32(const uint8_t* p) {
  uint32_t v = 0;
#if __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
  memcpy(&v, p, 4);
#else
  for (uint8_t i = 0; i < 4; ++i) v |= static_cast<uint32_t>(p[i]) << (8 * i);
#endif
  return v;
}
inline float get_f32(const uint8_t* p) {
  const uint32_t bits = get_u32(p);
  float v;
  memcpy(&v, &bits, 4);
  return v;
}

// The same by type, for the generic message codec (core/message_codec.h): one encoder and one
// decoder per field type, and arrays element by element. Every wire type is its own size in C++.
inline void put(uint8_t* p, uint8_t v) { put_u8(p, v); }
inline void put(uint8_t* p, uint16_t v) { put_u16(p, v); }
inline void put(uint8_t* p, int16_t v) { put_u16(p, static_cast<uint16_t>(v)); }
inline void put(uint8_t* p, uint32_t v) { put_u32(p, v); }
inline void put(uint8_t* p, float v) { put_f32(p, v); }
template <typename T, uint8_t N>
inline void put(uint8_t* p, const T (&v)[N]) {
  for (uint8_t i = 0; i < N; ++i) put(p + i * sizeof(T), v[i]);
}
inline void get(const uint8_t* p, uint8_t& v) { v = get_u8(p); }
inline void get(const uint8_t* p, uint16_t& v) { v = get_u16(p); }
inline void get(const uint8_t* p, int16_t& v) { v = static_cast<int16_t>(get_u16(p)); }
inline void get(const uint8_t* p, uint32_t& v) { v = get_u32(p); }
inline void get(const uint8_t* p, float& v) { v = get_f32(p); }
template <typename T, uint8_t N>
inline void get(const uint8_t* p, T (&v)[N]) {
  for (uint8_t i = 0; i < N; ++i) get(p + i * sizeof(T), v[i]);
}

// True for every number except NaN and +-infinity (exponent bits all ones). Works on the bits so it
// does not depend on the compiler's float flags.
inline bool finite(float v) {
  uint32_t bits;
  memcpy(&bits, &v, 4);
  return (bits & 0x7F800000UL) != 0x7F800000UL;
}

}  // namespace wire
