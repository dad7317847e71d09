// Frames: COBS(schema_hash:u16 | msg_id:u8 | seq:u8 | payload | [crc32:u32] | crc16:u16) 0x00,
// the CRC-32 only in frames of messages sent to the robot (eelproto::is_to_robot).
// The decoder works byte by byte from the UART and never acts on a frame that fails a check: each
// dropped frame is counted once in LinkCounters under the first check it failed. Its work per byte
// is bounded (COBS and both CRCs advance as each byte arrives), so a frame's end costs no burst.
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "cobs.h"
#include "link_counters.h"
#include "protocol_gen.h"

namespace frame {
constexpr uint8_t kOverhead = eelproto::kHeaderBytes + eelproto::kCrcBytes;
// Largest encoded frame without its delimiter, and the largest decoded frame that fits in it.
constexpr uint8_t kMaxEncoded = eelproto::kMaxFrameBytes - 1;
constexpr uint8_t kMaxDecoded = kMaxEncoded - 1;
constexpr uint8_t kMaxPayload = kMaxDecoded - kOverhead;
}  // namespace frame

struct Frame {
  uint8_t msg_id;
  uint8_t seq;
  uint8_t payload_len;
  const uint8_t* payload;  // points into the decoder's buffer: valid until the next push()
  uint32_t check;          // the frame's CRC-32 (to the robot) or CRC-16: same value, same frame
};

class FrameDecoder {
 public:
  // Feed one received byte; true when it completed a valid frame, then available as frame().
  bool push(uint8_t byte, LinkCounters& counters);
  const Frame& frame() const { return frame_; }
  // Forget a partial frame (after a reset).
  void clear();

 private:
  void emit(uint8_t byte);
  bool finish(LinkCounters& counters);

  uint8_t buf_[frame::kMaxDecoded] = {};
  uint8_t len_ = 0;      // decoded bytes of the frame so far
  uint8_t encoded_ = 0;  // encoded bytes since the last delimiter
  bool overflow_ = false;  // in an oversize frame: drop bytes up to the next delimiter
  CobsStream cobs_;
  // The CRC registers, stored complemented so that the all-zero state of a fresh decoder is the
  // CRCs' start (0xFFFF, 0xFFFFFFFF) and the decoder can live in .bss. The CRC-16 covers the
  // decoded bytes but the last 2 (itself), the CRC-32 all but the last 6 (itself and the CRC-16).
  uint16_t crc16_not_ = 0;
  uint32_t crc32_not_ = 0;
  Frame frame_{};
};

// Write one complete frame, delimiter included, to out (with the CRC-32 when msg_id is a message
// to the robot). Returns its length, or 0 when the payload is too large or out is too small.
size_t encode_frame(uint8_t msg_id, uint8_t seq, const uint8_t* payload, uint8_t payload_len,
                    uint8_t* out, size_t cap);
