// How often a command corrupted on the air still executes (docs/firmware.md, "Command
// integrity"): commands with random valid values are encoded, each byte is corrupted with a
// probability (XOR with a random non-zero mask, as the host's radio model does), and the bytes
// go through the robot's own decoder and command handling. A corrupted command "executes" when
// the robot acknowledges it: its bytes differ from what was sent, so it is not the command sent.
// The count of frames that a CRC-16 alone would have let through (protocol version 1: the same
// checks without the CRC-32) is kept beside it.
#pragma once
#include <stdint.h>
#include <string.h>

#include "cobs.h"
#include "crc16.h"
#include "frame_codec.h"
#include "message_codec.h"
#include "robot.h"
#include "settings_codec.h"
#include "settings_store.h"
#include "wire.h"

struct CorruptionStats {
  uint64_t frames = 0;             // commands sent
  uint64_t corrupted = 0;          // of which at least one byte (or the delimiter before) changed
  uint64_t acknowledged = 0;       // intact commands the robot executed
  uint64_t corrupted_executed = 0;  // corrupted commands the robot executed: the figure
  uint64_t passed_crc16 = 0;       // corrupted frames whose CRC-16 still matched
  uint64_t crc16_only_executed = 0;  // of those, valid commands: what CRC-16 alone would run
  uint64_t stopped_by_crc32 = 0;   // corrupted frames dropped by the CRC-32 (bad_crc32)
};

class CorruptionBench {
 public:
  // p: probability that a byte is corrupted. refresh_crc16: recompute the CRC-16 after the
  // corruption (as if it had failed to see it every time), so that only the CRC-32 and the range
  // checks stand between the corruption and the robot.
  CorruptionBench(double p, uint64_t seed, bool refresh_crc16)
      : threshold_(static_cast<uint64_t>(p * 18446744073709551616.0)),
        rng_(seed | 1),
        refresh_crc16_(refresh_crc16) {
    // A robot set up with the defaults saved (a blank EEPROM would refuse Start).
    memset(eeprom_, 0xFF, sizeof eeprom_);
    settings_to_image(eelproto::settings_defaults(), eeprom_, 1);
    robot_.reset(0, BootInfo{1, 0, false}, eeprom_);
  }

  void run(uint64_t frames) {
    for (uint64_t k = 0; k < frames; ++k) send_one();
  }
  const CorruptionStats& stats() const { return stats_; }

 private:
  uint64_t next() {  // xorshift64*
    rng_ ^= rng_ >> 12;
    rng_ ^= rng_ << 25;
    rng_ ^= rng_ >> 27;
    return rng_ * 2685821657736338717ULL;
  }
  float uniform(float lo, float hi) {
    return lo + (hi - lo) * static_cast<float>(next() >> 40) * (1.0f / 16777216.0f);
  }

  template <class M>
  size_t encode(const M& m, uint8_t* out) {
    uint8_t p[64] = {};
    eelproto::pack(m, p);
    return encode_frame(static_cast<uint8_t>(M::kId), seq_++, p, M::kPayloadBytes, out, 64);
  }

  // A command that moves the robot (or would change how), with valid random values.
  size_t command(uint8_t* out) {
    switch (next() % 6) {
      case 0:
        return encode(eelproto::SetGait{uniform(0, 1.5f), uniform(0, 20), uniform(-3.14f, 3.14f),
                                        uniform(0, 100), uniform(0, 100), uniform(0, 100)},
                      out);
      case 1:
        return encode(eelproto::SetOffset{uniform(-1, 1)}, out);
      case 2:
        return encode(eelproto::SetGains{uniform(0, 100), uniform(0, 10), uniform(0, 10)}, out);
      case 3:
        return encode(eelproto::Start{}, out);
      case 4:
        return encode(eelproto::Stop{}, out);
      default:
        return encode(eelproto::SetSetting{static_cast<uint8_t>(1 + next() % 17),
                                           static_cast<uint8_t>(next() % 5), uniform(-2, 2)},
                      out);
    }
  }

  // What protocol version 1 would have done with the bytes of one received frame: the same
  // checks in the same order, the CRC-16 the only CRC.
  bool crc16_alone_executes(const uint8_t* encoded, size_t n) {
    uint8_t raw[64];
    const int len = cobs_decode(encoded, n, raw, sizeof raw);
    if (len < frame::kOverhead) return false;
    const uint8_t body = static_cast<uint8_t>(len - eelproto::kCrcBytes);
    if (crc16_ccitt_false(raw, body) != wire::get_u16(raw + body)) return false;
    ++stats_.passed_crc16;
    const int16_t want = eelproto::payload_bytes(raw[2]);
    if (wire::get_u16(raw) != eelproto::kSchemaHash || want < 0 || !eelproto::is_to_robot(raw[2]) ||
        len != frame::kOverhead + want + eelproto::kCommandCrcBytes) {
      return false;
    }
    const uint8_t* payload = raw + eelproto::kHeaderBytes;
    switch (static_cast<eelproto::MsgId>(raw[2])) {
      case eelproto::MsgId::SetGait: return valid<eelproto::SetGait>(payload);
      case eelproto::MsgId::SetOffset: return valid<eelproto::SetOffset>(payload);
      case eelproto::MsgId::SetGains: return valid<eelproto::SetGains>(payload);
      default: return true;  // no fields to check (SetSetting's are checked by the robot: close)
    }
  }
  template <class M>
  bool valid(const uint8_t* payload) {
    M m;
    eelproto::unpack(m, payload);
    return eelproto::validate(m) == 0;
  }

  void send_one() {
    uint8_t out[64], sent[64];
    const size_t n = command(out);
    memcpy(sent, out, n);
    bool hit = false;
    for (size_t i = 0; i < n; ++i) {
      if (next() < threshold_) {
        uint8_t mask;
        do mask = static_cast<uint8_t>(next()); while (mask == 0);
        out[i] ^= mask;
        hit = true;
      }
    }
    if (hit && refresh_crc16_ && out[n - 1] == 0) refresh(out, n);
    // Tainted: the bytes on the air are not the ones sent (a corruption of the CRC-16 alone that
    // refresh() repaired leaves the command intact), or the frame before lost its delimiter.
    const bool tainted = delimiter_lost_ || memcmp(out, sent, n) != 0;
    delimiter_lost_ = out[n - 1] != 0;
    ++stats_.frames;
    if (tainted) ++stats_.corrupted;
    const uint16_t crc32_before = robot_.counters().bad_crc32;
    for (size_t i = 0; i < n; ++i) {
      if (out[i] != 0) {
        if (received_ < sizeof received_bytes_) received_bytes_[received_] = out[i];
        ++received_;
      } else {
        if (tainted && received_ <= sizeof received_bytes_ &&
            crc16_alone_executes(received_bytes_, received_)) {
          ++stats_.crc16_only_executed;
        }
        received_ = 0;
      }
      robot_.on_rx_byte(out[i], 0);
    }
    stats_.stopped_by_crc32 += static_cast<uint16_t>(robot_.counters().bad_crc32 - crc32_before);
    const int acks = take_acks();
    if (tainted) {
      stats_.corrupted_executed += acks;
    } else {
      stats_.acknowledged += acks;
    }
  }

  // Decode the corrupted frame, put a CRC-16 that matches it, encode it again.
  void refresh(uint8_t* out, size_t n) {
    uint8_t raw[64];
    const int len = cobs_decode(out, n - 1, raw, sizeof raw);
    if (len < frame::kOverhead) return;
    const uint8_t body = static_cast<uint8_t>(len - eelproto::kCrcBytes);
    wire::put_u16(raw + body, crc16_ccitt_false(raw, body));
    uint8_t again[64];
    const size_t m = cobs_encode(raw, static_cast<size_t>(len), again, sizeof again);
    if (m != n - 1) return;  // the same length only, so the stream stays in step
    memcpy(out, again, m);
  }

  int take_acks() {
    int acks = 0;
    Robot::TxQueue& tx = robot_.tx();
    while (!tx.empty()) {
      if (!replies_.push(tx.pop(), reply_counters_)) continue;
      if (replies_.frame().msg_id == static_cast<uint8_t>(eelproto::MsgId::Ack)) ++acks;
    }
    return acks;
  }

  Robot robot_;
  uint8_t eeprom_[kSettingsEepromBytes];
  FrameDecoder replies_;
  LinkCounters reply_counters_{};
  CorruptionStats stats_;
  uint64_t threshold_;
  uint64_t rng_;
  bool refresh_crc16_;
  bool delimiter_lost_ = false;
  uint8_t seq_ = 0;
  uint8_t received_bytes_[256];
  size_t received_ = 0;
};
