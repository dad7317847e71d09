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

// Decodes the encoded bytes of one frame as they arrive, one at a time (so a receiver never
// decodes a whole frame at once). Every block starts with a code byte: 1 + the data bytes that
// follow; a block shorter than 254 data bytes stands for its data and a zero, except the last.
class CobsStream {
 public:
  void clear() {
    left_ = 0;
    code_ = 0;
  }
  // Push one encoded byte (never 0: zeros delimit frames). Returns true when it releases a decoded
  // byte, written to `out`: a data byte, or the zero implied by the block it closes.
  bool push(uint8_t byte, uint8_t& out) {
    if (left_ > 0) {
      --left_;
      out = byte;
      return true;
    }
    const bool implied_zero = code_ != 0 && code_ != 0xFF;  // a block before this one, not full
    code_ = byte;
    left_ = static_cast<uint8_t>(byte - 1);
    out = 0;
    return implied_zero;
  }
  // At the frame's delimiter: true when the last block was complete (valid COBS).
  bool complete() const { return left_ == 0; }

 private:
  uint8_t left_ = 0;  // data bytes still due in the current block
  uint8_t code_ = 0;  // code byte of the current block; 0 before the first
};

// Decode n encoded bytes (no delimiter) into dst (capacity cap). Returns the decoded length, or -1
// when the input is not valid COBS (a zero byte, a block running past the end) or dst is too small.
// In-place decoding (dst == src) is allowed: the output never overtakes the input.
int cobs_decode(const uint8_t* src, size_t n, uint8_t* dst, size_t cap);
