#include "cobs.h"

size_t cobs_encode(const uint8_t* src, size_t n, uint8_t* dst, size_t cap) {
  if (cap < cobs_max_encoded(n)) return 0;
  size_t code_at = 0;  // where the current block's length code goes
  size_t out = 1;
  uint8_t code = 1;    // 1 + bytes in the current block
  for (size_t i = 0; i < n; ++i) {
    if (src[i] == 0) {
      dst[code_at] = code;
      code_at = out++;
      code = 1;
      continue;
    }
    dst[out++] = src[i];
    if (++code == 0xFF) {  // a full block of 254 data bytes: it carries no implied zero
      dst[code_at] = code;
      code_at = out++;
      code = 1;
    }
  }
  dst[code_at] = code;
  return out;
}

int cobs_decode(const uint8_t* src, size_t n, uint8_t* dst, size_t cap) {
  CobsStream stream;
  size_t out = 0;
  for (size_t i = 0; i < n; ++i) {
    uint8_t b;
    if (src[i] == 0) return -1;
    if (!stream.push(src[i], b)) continue;
    if (out >= cap) return -1;
    dst[out++] = b;
  }
  return stream.complete() ? static_cast<int>(out) : -1;
}
