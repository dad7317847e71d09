// libFuzzer target for COBS (core/cobs.h): decoding any bytes either fails or gives data that
// encodes back to the same bytes; the only other valid form ends with a full block (code 0xFF),
// which the encoder follows with an empty block.
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "cobs.h"

namespace {
void require(bool ok) {
  if (!ok) __builtin_trap();
}

// Whether the input's last block is a full one (code 0xFF): walk the codes.
bool ends_with_full_block(const uint8_t* data, size_t size) {
  size_t at = 0;
  uint8_t code = 0;
  while (at < size) {
    code = data[at];
    at += code;
  }
  return code == 0xFF;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static uint8_t decoded[4096], encoded[4200], again[4096];
  // No bytes are no encoding (the empty data encodes to one block: 0x01); frames end there too.
  if (size == 0 || size > sizeof decoded) return 0;
  const int n = cobs_decode(data, size, decoded, sizeof decoded);
  if (n < 0) return 0;
  const size_t m = cobs_encode(decoded, static_cast<size_t>(n), encoded, sizeof encoded);
  require(m > 0 && memchr(encoded, 0, m) == nullptr);
  if (ends_with_full_block(data, size)) {
    require(m == size + 1 && memcmp(encoded, data, size) == 0 && encoded[size] == 0x01);
  } else {
    require(m == size && memcmp(encoded, data, size) == 0);
  }
  require(cobs_decode(encoded, m, again, sizeof again) == n);
  require(memcmp(again, decoded, static_cast<size_t>(n)) == 0);
  return 0;
}
