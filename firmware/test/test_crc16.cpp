#include "check.h"
#include "crc16.h"

TEST(crc16_matches_published_check_value_for_123456789) {
  const uint8_t msg[] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
  CHECK_EQ(crc16_ccitt_false(msg, sizeof msg), 0x29B1);
}

TEST(crc16_of_nothing_is_the_initial_value) { CHECK_EQ(crc16_ccitt_false(nullptr, 0), 0xFFFF); }

TEST(crc16_continued_over_pieces_equals_crc16_in_one_go) {
  const uint8_t msg[] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
  const uint16_t part = crc16_ccitt_false_update(kCrc16Init, msg, 4);
  CHECK_EQ(crc16_ccitt_false_update(part, msg + 4, 5), 0x29B1);
}

TEST(crc16_detects_every_single_bit_flip) {
  uint8_t msg[] = {0x84, 0x8D, 0x02, 0x07, 0x00, 0x00, 0x00, 0x3F};
  const uint16_t good = crc16_ccitt_false(msg, sizeof msg);
  for (unsigned bit = 0; bit < 8 * sizeof msg; ++bit) {
    msg[bit / 8] ^= static_cast<uint8_t>(1U << (bit % 8));
    CHECK(crc16_ccitt_false(msg, sizeof msg) != good);
    msg[bit / 8] ^= static_cast<uint8_t>(1U << (bit % 8));
  }
}
