#include "command_link.h"

void CommandLink::reset(uint32_t now_us) {
  decoder_.clear();
  counters_ = LinkCounters{};
  watchdog_.feed(now_us);
  tx_.clear();
  tx_seq_ = 0;
  have_rx_seq_ = false;
  last_answer_ = kNoAnswer;
}

// Sequence numbers: a gap counts as lost frames; the previous frame again (same number, same CRC:
// a radio retry) is a duplicate; any other jump backwards by more than half the range is taken as
// a host restart and resynchronises without counting. Hello always resynchronises.
bool CommandLink::is_duplicate(const Frame& f) {
  const bool resync = !have_rx_seq_ || f.msg_id == static_cast<uint8_t>(eelproto::MsgId::Hello);
  if (!resync && f.seq == last_rx_seq_ && f.check == last_check_) return true;
  const uint8_t gap = static_cast<uint8_t>(f.seq - static_cast<uint8_t>(last_rx_seq_ + 1));
  if (!resync && gap < 0x80) counters_.lost = static_cast<uint16_t>(counters_.lost + gap);
  have_rx_seq_ = true;
  last_rx_seq_ = f.seq;
  last_check_ = f.check;
  return false;
}

const Frame* CommandLink::push(uint8_t byte, uint32_t now_us) {
  if (!decoder_.push(byte, counters_)) return nullptr;
  const Frame& f = decoder_.frame();
  if (!eelproto::is_to_robot(f.msg_id)) {
    ++counters_.bad_direction;
    return nullptr;
  }
  // Only a command with a new sequence number, ahead of the last one, proves that the host is
  // there: a replay of the last frame (a stuck radio, a host retrying in a loop) is answered but
  // must not hold off the fade and FAILSAFE (docs/firmware.md, "Failsafe").
  const uint8_t ahead = static_cast<uint8_t>(f.seq - last_rx_seq_);
  if (!have_rx_seq_ || (ahead != 0 && ahead < 0x80)) watchdog_.feed(now_us);
  if (is_duplicate(f)) {
    ++counters_.duplicates;
    if (last_answer_ == kNoAnswer) return &f;
    answer(f.msg_id, f.seq, last_answer_);
    return nullptr;
  }
  ++counters_.frames_ok;
  last_answer_ = kNoAnswer;
  return &f;
}

void CommandLink::answer(uint8_t msg_id, uint8_t seq, uint8_t reason) {
  if (have_rx_seq_ && seq == last_rx_seq_) last_answer_ = reason;
  if (reason == 0) {
    reply(eelproto::Ack{msg_id, seq});
  } else {
    reply(eelproto::Refuse{msg_id, seq, reason});
  }
}

void CommandLink::ack(uint8_t msg_id, uint8_t seq) { answer(msg_id, seq, 0); }

void CommandLink::refuse(uint8_t msg_id, uint8_t seq, uint8_t reason) {
  answer(msg_id, seq, reason);
}

void CommandLink::send_frame(uint8_t msg_id, const uint8_t* payload, uint8_t len) {
  uint8_t buf[eelproto::kMaxFrameBytes];
  const size_t n = encode_frame(msg_id, tx_seq_, payload, len, buf, sizeof(buf));
  if (n == 0 || !tx_.push_all(buf, n)) {
    ++counters_.tx_dropped;
    return;
  }
  ++tx_seq_;
}
