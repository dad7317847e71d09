// The robot's end of the radio link: decodes the bytes from the host into commands, keeps the
// sequence numbers, answers duplicates, feeds the failsafe timer and queues what the robot sends.
// docs/firmware.md, "Link".
#pragma once
#include <stdint.h>

#include "byte_queue.h"
#include "frame_codec.h"
#include "link_counters.h"
#include "link_watchdog.h"
#include "message_codec.h"

class CommandLink {
 public:
  using TxQueue = ByteQueue<128>;
  // Replies first (docs/firmware.md, "Link"): an answer to a command may use the whole queue; a
  // frame the robot sends on its own (Telemetry, the periodic Status) is queued only when it leaves
  // this much free for the replies that may come while it goes out: the largest frame, so any one
  // reply, and as much as the UART's receive buffer can hold of commands whose answers (Ack,
  // Refuse, Setting) are no longer than they are.
  static constexpr uint8_t kReplyRoomBytes = eelproto::kMaxFrameBytes;

  // Bytes of a frame the robot sends with a payload of payload_bytes: header, payload, CRC-16,
  // COBS's code byte (one: every frame is under 254 bytes) and the delimiter.
  static_assert(eelproto::kMaxFrameBytes < 254, "frame_bytes counts one COBS code byte");
  static constexpr uint8_t frame_bytes(uint8_t payload_bytes) {
    return static_cast<uint8_t>(eelproto::kHeaderBytes + payload_bytes + eelproto::kCrcBytes + 2);
  }

  void reset(uint32_t now_us);
  // One received byte. Returns the command to execute, or nullptr: nothing complete yet, a bad
  // frame (counted), a frame of a message only the robot sends (counted as bad_direction and
  // ignored: an echoing radio must not keep the link alive), or a repeat of the previous command
  // (counted as a duplicate and answered as the first copy was, not executed again; a query has
  // no stored answer and is returned to be answered again). Only a command whose sequence number
  // is ahead of the last one feeds the watchdog.
  const Frame* push(uint8_t byte, uint32_t now_us);

  // Answers to the command last returned by push() (or, for a save, the command that asked).
  void ack(uint8_t msg_id, uint8_t seq);
  void refuse(uint8_t msg_id, uint8_t seq, uint8_t reason);
  // An answer with data (Version, Setting, the Status asked for): may use the whole queue. A
  // reply that finds no room is dropped and counted (tx_dropped): the queue then holds other
  // replies, and of the robot's own frames only what went in while kReplyRoomBytes were free.
  template <typename M>
  void reply(const M& m) {
    send(m);
  }
  // Whether a frame the robot sends on its own with this payload may be queued now: it must leave
  // kReplyRoomBytes free. When not, the robot keeps it for its next control update (nothing is
  // dropped or counted), so a periodic frame never takes room a reply needs.
  bool periodic_fits(uint8_t payload_bytes) const {
    return tx_.space() >= static_cast<uint16_t>(frame_bytes(payload_bytes) + kReplyRoomBytes);
  }
  // A frame the robot sends on its own (Telemetry, Status), after periodic_fits said yes.
  template <typename M>
  void send_periodic(const M& m) {
    send(m);
  }

  const LinkCounters& counters() const { return counters_; }
  const LinkWatchdog& watchdog() const { return watchdog_; }
  TxQueue& tx() { return tx_; }

 private:
  static constexpr uint8_t kNoAnswer = 0xFF;  // last_answer_: nothing stored (a query, or none)
  template <typename M>
  void send(const M& m) {
    uint8_t p[M::kPayloadBytes];
    eelproto::pack(m, p);
    send_frame(static_cast<uint8_t>(M::kId), p, sizeof(p));
  }
  void send_frame(uint8_t msg_id, const uint8_t* payload, uint8_t len);
  void answer(uint8_t msg_id, uint8_t seq, uint8_t reason);
  // Sequence check of a new command: counts lost frames, tells a duplicate.
  bool is_duplicate(const Frame& f);

  FrameDecoder decoder_;
  LinkCounters counters_{};
  LinkWatchdog watchdog_;
  TxQueue tx_;
  uint32_t last_check_ = 0;    // CRC of the last command: a duplicate is the same frame again
  uint8_t tx_seq_ = 0;
  uint8_t last_rx_seq_ = 0;
  uint8_t last_answer_ = 0;    // 0: Ack; a RefuseReason; kNoAnswer
  bool have_rx_seq_ = false;
};
