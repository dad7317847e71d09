#include "crc16.h"

uint16_t crc16_ccitt_false_step(uint16_t crc, uint8_t byte) {
  crc = static_cast<uint16_t>(crc ^ (static_cast<uint16_t>(byte) << 8));
  for (uint8_t bit = 0; bit < 8; ++bit) {
    crc = (crc & 0x8000U) ? static_cast<uint16_t>((crc << 1) ^ 0x1021U)
                          : static_cast<uint16_t>(crc << 1);
  }
  return crc;
}

uint16_t crc16_ccitt_false_update(uint16_t crc, const uint8_t* data, size_t n) {
  for (size_t i = 0; i < n; ++i) crc = crc16_ccitt_false_step(crc, data[i]);
  return crc;
}
