#include "crc16.h"

// A byte at a time without a table: the eight steps of the bitwise division by 0x1021 folded
// into shifts of the byte (0x1021 = x^12 + x^5 + 1). The same CRC as the bit loop, ~5 times fewer
// cycles on the AVR.
uint16_t crc16_ccitt_false_step(uint16_t crc, uint8_t byte) {
  uint16_t x = static_cast<uint16_t>((crc >> 8) ^ byte);
  x = static_cast<uint16_t>(x ^ (x >> 4));
  return static_cast<uint16_t>((crc << 8) ^ (x << 12) ^ (x << 5) ^ x);
}

uint16_t crc16_ccitt_false_update(uint16_t crc, const uint8_t* data, size_t n) {
  for (size_t i = 0; i < n; ++i) crc = crc16_ccitt_false_step(crc, data[i]);
  return crc;
}
