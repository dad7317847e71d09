// Consistent Overhead Byte Stuffing: removes every zero byte from a frame so that a single zero can
// delimit frames, and a receiver resynchronises at the next zero after any garbage.
#pragma once
#include <stddef.h>
#include <stdint.h>

// Encoded size in the worst case (no delimiter): n + 1 + n / 254.
constexpr size_t cobs_max_encoded(size_t n) { return n + 1 + n / 254; }

// Encode n bytes from src into dst (capacity cap). Returns the encoded length (no delimiter), or 0
// when dst is too small. src and dst must not overlap.
size_t cobs_encode(const uint8_t* src, size_t n, uint8_t* dst, size_t cap);

// Decode n encoded bytes (no delimiter) into dst (capacity cap). Returns the decoded length, or -1
// when the input is not valid COBS (a zero byte, a block running past the end) or dst is too small.
// In-place decoding (dst == src) is allowed: the output never overtakes the input.
int cobs_decode(const uint8_t* src, size_t n, uint8_t* dst, size_t cap);
