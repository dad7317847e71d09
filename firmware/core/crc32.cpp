#include "crc32.h"

#include "flash_table.h"

namespace {
// The register after shifting a nibble out of it: the CRC of each 4-bit value, 64 bytes of flash
// (a byte table would take 1 KB). Two lookups a byte instead of eight shift-and-xor steps.
EEL_FLASH_TABLE constexpr uint32_t kNibble[16] = {
    0x00000000UL, 0x1DB71064UL, 0x3B6E20C8UL, 0x26D930ACUL, 0x76DC4190UL, 0x6B6B51F4UL,
    0x4DB26158UL, 0x5005713CUL, 0xEDB88320UL, 0xF00F9344UL, 0xD6D6A3E8UL, 0xCB61B38CUL,
    0x9B64C2B0UL, 0x86D3D2D4UL, 0xA00AE278UL, 0xBDBDF21CUL,
};

uint32_t shift_nibble(uint32_t reg) { return (reg >> 4) ^ flash_read_u32(&kNibble[reg & 0x0F]); }
}  // namespace

uint32_t crc32_iso_hdlc_step(uint32_t reg, uint8_t byte) {
  reg ^= byte;
  return shift_nibble(shift_nibble(reg));
}

uint32_t crc32_iso_hdlc(const uint8_t* data, size_t n) {
  uint32_t reg = kCrc32Init;
  for (size_t i = 0; i < n; ++i) reg = crc32_iso_hdlc_step(reg, data[i]);
  return ~reg;
}
