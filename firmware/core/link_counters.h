// Link statistics. Every dropped frame increments exactly one of the bad_* counters. All counters
// wrap at 65536 (the host looks at differences).
#pragma once
#include <stdint.h>

struct LinkCounters {
  uint16_t frames_ok;       // passed every check and were handled (acked or refused)
  uint16_t bad_cobs;        // garbage: not valid COBS
  uint16_t bad_short;       // truncated: shorter than header + CRC
  uint16_t bad_oversize;    // more than kMaxFrameBytes before a delimiter
  uint16_t bad_crc;         // CRC-16 mismatch
  uint16_t bad_schema;      // another protocol definition (schema hash)
  uint16_t bad_unknown_id;  // an id this schema does not define
  uint16_t bad_length;      // payload size does not match the id
  uint16_t bad_crc32;       // a command whose CRC-32 does not match
  uint16_t bad_direction;   // a message only the robot sends (its own frames echoed back)
  uint16_t duplicates;      // the previous frame again (a radio retry): acknowledged, not executed
  uint16_t lost;            // gaps in the sequence numbers
  uint16_t tx_dropped;      // frames the robot could not queue for sending

  uint16_t bad_total() const {
    return static_cast<uint16_t>(bad_cobs + bad_short + bad_oversize + bad_crc + bad_schema +
                                 bad_unknown_id + bad_length + bad_crc32 + bad_direction);
  }
};
