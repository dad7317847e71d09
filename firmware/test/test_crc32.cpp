#include "check.h"
#include "crc32.h"

TEST(crc32_matches_published_check_value_for_123456789) {
  const uint8_t msg[] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
  CHECK_EQ(crc32_iso_hdlc(msg, sizeof msg), 0xCBF43926UL);
}

TEST(crc32_of_nothing_is_zero) { CHECK_EQ(crc32_iso_hdlc(nullptr, 0), 0UL); }

TEST(crc32_stepped_byte_by_byte_equals_crc32_in_one_go) {
  const uint8_t msg[] = {0x84, 0x8D, 0x02, 0x07, 0x00, 0x00, 0x80, 0x3F, 0x55};
  uint32_t reg = kCrc32Init;
  for (uint8_t b : msg) reg = crc32_iso_hdlc_step(reg, b);
  CHECK_EQ(~reg, crc32_iso_hdlc(msg, sizeof msg));
}

TEST(crc32_detects_every_burst_of_up_to_32_bits) {
  uint8_t msg[12] = {0x84, 0x8D, 0x02, 0x07, 0x00, 0x00, 0x80, 0x3F, 0x55, 0xAA, 0x01, 0xFE};
  const uint32_t good = crc32_iso_hdlc(msg, sizeof msg);
  for (unsigned start = 0; start + 32 <= 8 * sizeof msg; start += 3) {
    for (unsigned len = 1; len <= 32; len += 5) {  // first and last bit of the burst flipped
      msg[start / 8] ^= static_cast<uint8_t>(1U << (start % 8));
      const unsigned last = start + len - 1;
      if (len > 1) msg[last / 8] ^= static_cast<uint8_t>(1U << (last % 8));
      CHECK(crc32_iso_hdlc(msg, sizeof msg) != good);
      msg[start / 8] ^= static_cast<uint8_t>(1U << (start % 8));
      if (len > 1) msg[last / 8] ^= static_cast<uint8_t>(1U << (last % 8));
    }
  }
}
