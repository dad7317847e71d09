#include <stdint.h>
#include <string.h>

#include "check.h"
#include "cobs.h"

namespace {
bool encodes_to(const uint8_t* in, size_t n, const uint8_t* want, size_t want_n) {
  uint8_t out[600];
  const size_t got = cobs_encode(in, n, out, sizeof out);
  return got == want_n && memcmp(out, want, want_n) == 0;
}
}  // namespace

TEST(cobs_encodes_the_textbook_examples) {
  const uint8_t a[] = {0x00}, a_enc[] = {0x01, 0x01};
  const uint8_t b[] = {0x00, 0x00}, b_enc[] = {0x01, 0x01, 0x01};
  const uint8_t c[] = {0x11, 0x22, 0x00, 0x33}, c_enc[] = {0x03, 0x11, 0x22, 0x02, 0x33};
  const uint8_t d[] = {0x11, 0x22, 0x33, 0x44}, d_enc[] = {0x05, 0x11, 0x22, 0x33, 0x44};
  const uint8_t e[] = {0x11, 0x00, 0x00, 0x00}, e_enc[] = {0x02, 0x11, 0x01, 0x01, 0x01};
  CHECK(encodes_to(a, sizeof a, a_enc, sizeof a_enc));
  CHECK(encodes_to(b, sizeof b, b_enc, sizeof b_enc));
  CHECK(encodes_to(c, sizeof c, c_enc, sizeof c_enc));
  CHECK(encodes_to(d, sizeof d, d_enc, sizeof d_enc));
  CHECK(encodes_to(e, sizeof e, e_enc, sizeof e_enc));
}

TEST(cobs_round_trips_every_length_up_to_600_without_zero_bytes) {
  uint8_t in[600], enc[620], dec[600];
  uint32_t x = 12345;
  for (size_t n = 0; n <= sizeof in; ++n) {
    for (size_t i = 0; i < n; ++i) {
      x = x * 1103515245u + 12345u;
      in[i] = (x >> 16) % 3 == 0 ? 0 : static_cast<uint8_t>(x >> 8);  // many zeros, runs of 254+
    }
    if (n % 7 == 0) memset(in, 0xAB, n);  // long zero-free runs cross the 254-byte blocks
    const size_t m = cobs_encode(in, n, enc, sizeof enc);
    CHECK(m >= n + 1 && m <= cobs_max_encoded(n));
    CHECK(memchr(enc, 0, m) == nullptr);
    const int back = cobs_decode(enc, m, dec, sizeof dec);
    CHECK_EQ(back, static_cast<int>(n));
    CHECK(memcmp(in, dec, n) == 0);
  }
}

TEST(cobs_decodes_in_place) {
  const uint8_t in[] = {0x11, 0x00, 0x22, 0x00, 0x00, 0x33};
  uint8_t buf[16];
  const size_t m = cobs_encode(in, sizeof in, buf, sizeof buf);
  CHECK_EQ(cobs_decode(buf, m, buf, sizeof buf), static_cast<int>(sizeof in));
  CHECK(memcmp(buf, in, sizeof in) == 0);
}

TEST(cobs_decode_rejects_a_zero_byte_and_a_block_past_the_end) {
  uint8_t out[16];
  const uint8_t zero_code[] = {0x00, 0x11};
  const uint8_t zero_inside[] = {0x03, 0x11, 0x00};
  const uint8_t past_end[] = {0x05, 0x11, 0x22};
  CHECK_EQ(cobs_decode(zero_code, sizeof zero_code, out, sizeof out), -1);
  CHECK_EQ(cobs_decode(zero_inside, sizeof zero_inside, out, sizeof out), -1);
  CHECK_EQ(cobs_decode(past_end, sizeof past_end, out, sizeof out), -1);
}

TEST(cobs_refuses_output_buffers_that_are_too_small) {
  const uint8_t in[] = {1, 2, 3, 4};
  uint8_t out[8];
  CHECK_EQ(cobs_encode(in, sizeof in, out, 4), 0u);
  const uint8_t enc[] = {0x05, 1, 2, 3, 4};
  CHECK_EQ(cobs_decode(enc, sizeof enc, out, 3), -1);
}
