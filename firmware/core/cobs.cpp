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
  size_t in = 0;
  size_t out = 0;
  while (in < n) {
    const uint8_t code = src[in++];
    if (code == 0 || in + code - 1 > n) return -1;
    for (uint8_t k = 1; k < code; ++k) {
      const uint8_t b = src[in++];
      if (b == 0 || out >= cap) return -1;
      dst[out++] = b;
    }
    if (code != 0xFF && in < n) {  // the implied zero, except after the last block
      if (out >= cap) return -1;
      dst[out++] = 0;
    }
  }
  return static_cast<int>(out);
}
