#include "crc32.h"

uint32_t crc32_iso_hdlc_step(uint32_t reg, uint8_t byte) {
  reg ^= byte;
  for (uint8_t bit = 0; bit < 8; ++bit) {
    reg = (reg & 1UL) ? (reg >> 1) ^ 0xEDB88320UL : reg >> 1;
  }
  return reg;
}

uint32_t crc32_iso_hdlc(const uint8_t* data, size_t n) {
  uint32_t reg = kCrc32Init;
  for (size_t i = 0; i < n; ++i) reg = crc32_iso_hdlc_step(reg, data[i]);
  return ~reg;
}
