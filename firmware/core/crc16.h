// CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor.
// Check value: crc16_ccitt_false("123456789") == 0x29B1.
#pragma once
#include <stddef.h>
#include <stdint.h>

constexpr uint16_t kCrc16Init = 0xFFFF;

// One byte more (the frame decoder feeds the CRC as bytes arrive, so no frame costs a burst).
// Without a table: a 512-byte table would cost 3 % of the Nano's flash.
uint16_t crc16_ccitt_false_step(uint16_t crc, uint8_t byte);

// Continue a CRC over more bytes (start with kCrc16Init).
uint16_t crc16_ccitt_false_update(uint16_t crc, const uint8_t* data, size_t n);

inline uint16_t crc16_ccitt_false(const uint8_t* data, size_t n) {
  return crc16_ccitt_false_update(kCrc16Init, data, n);
}
