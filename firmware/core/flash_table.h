// Constant tables in program memory. On the AVR const data is copied to RAM at boot unless it is
// placed in flash (PROGMEM) and read back with its own instruction (LPM): the one thing core/
// knows about the chip it may run on. Everywhere else a table is plain memory.
#pragma once
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#ifdef __AVR__
#include <avr/pgmspace.h>
#define EEL_FLASH_TABLE PROGMEM
// Copy one row of a table marked EEL_FLASH_TABLE.
inline void flash_read(void* out, const void* row, size_t n) { memcpy_P(out, row, n); }
inline uint32_t flash_read_u32(const uint32_t* p) { return pgm_read_dword(p); }
#else
#define EEL_FLASH_TABLE
inline void flash_read(void* out, const void* row, size_t n) { memcpy(out, row, n); }
inline uint32_t flash_read_u32(const uint32_t* p) { return *p; }
#endif
