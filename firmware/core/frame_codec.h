// Frames: COBS(schema_hash:u16 | msg_id:u8 | seq:u8 | payload | crc16:u16) 0x00.
// The decoder works byte by byte from the UART and never acts on a frame that fails a check: each
// dropped frame is counted once in LinkCounters under the first check it failed.
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "link_counters.h"
#include "protocol_gen.h"

namespace frame {
constexpr uint8_t kOverhead = eelproto::kHeaderBytes + eelproto::kCrcBytes;
// Largest encoded frame without its delimiter, and the largest decoded frame that fits in it.
constexpr uint8_t kMaxEncoded = eelproto::kMaxFrameBytes - 1;
constexpr uint8_t kMaxPayload = kMaxEncoded - 1 - kOverhead;
}  // namespace frame

struct Frame {
  uint8_t msg_id;
  uint8_t seq;
  uint8_t payload_len;
  const uint8_t* payload;  // points into the decoder's buffer: valid until the next push()
};

class FrameDecoder {
 public:
  // Feed one received byte; true when it completed a valid frame, then available as frame().
  bool push(uint8_t byte, LinkCounters& counters);
  const Frame& frame() const { return frame_; }
  // Forget a partial frame (after a reset).
  void clear() { len_ = 0; overflow_ = false; }

 private:
  bool finish(LinkCounters& counters);

  uint8_t buf_[frame::kMaxEncoded] = {};
  uint8_t len_ = 0;
  bool overflow_ = false;  // in an oversize frame: drop bytes up to the next delimiter
  Frame frame_{};
};

// Write one complete frame, delimiter included, to out. Returns its length, or 0 when the payload is
// too large for a frame or out is too small.
size_t encode_frame(uint8_t msg_id, uint8_t seq, const uint8_t* payload, uint8_t payload_len,
                    uint8_t* out, size_t cap);
