// CRC-32/ISO-HDLC (the CRC of zlib, Ethernet and PNG): reflected poly 0xEDB88320, init and final
// xor 0xFFFFFFFF. Check value: crc32_iso_hdlc("123456789") == 0xCBF43926. Frames sent to the robot
// carry it besides the CRC-16 (docs/firmware.md, "Command integrity").
#pragma once
#include <stddef.h>
#include <stdint.h>

constexpr uint32_t kCrc32Init = 0xFFFFFFFFUL;

// One byte more into the register (start with kCrc32Init; the CRC is the register's complement).
uint32_t crc32_iso_hdlc_step(uint32_t reg, uint8_t byte);

uint32_t crc32_iso_hdlc(const uint8_t* data, size_t n);
