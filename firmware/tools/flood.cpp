// flood: a line-rate stream of one kind of traffic to the robot, as a --uart-in file for
// tools/eel_avrsim (docs/firmware.md, "Measured figures": the control period and update time
// under each kind). The host session first says Hello, sets a gait and starts the robot, then the
// flood fills the line back to back (57600 baud 8N1: 5760 bytes/s, one frame after the other)
// until DURATION_MS, with the host's keep-alive SetOffset every 300 ms in it, so that the robot
// runs throughout and the failsafe does not end the test. A SaveSettings before the Start makes
// the first ~0.35 s of the flood also a save in progress.
//
//   flood KIND DURATION_MS [SEED] > uart_in.txt
//
// KIND: commands (SetGait and SetOffset, each acknowledged), queries (GetStatus, Hello,
// GetSetting: the largest answers), garbage (random bytes), corrupted (commands with a byte
// damaged: CRC failures), echoes (the robot's own Telemetry and Status frames coming back),
// replays (the last command again and again: duplicates), mixed (a random kind each frame).
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "frame_codec.h"
#include "message_codec.h"

namespace {
constexpr double kByteUs = 10 * 1e6 / eelproto::kBaud;  // 8N1: 10 bit times a byte
constexpr uint32_t kFloodStartUs = 200000;
constexpr uint32_t kKeepAliveUs = 300000;

uint64_t g_rng = 1;
uint32_t rnd() {  // xorshift64*
  g_rng ^= g_rng >> 12;
  g_rng ^= g_rng << 25;
  g_rng ^= g_rng >> 27;
  return static_cast<uint32_t>((g_rng * 2685821657736338717ULL) >> 32);
}

struct Line {
  uint8_t bytes[eelproto::kMaxFrameBytes * 2];
  size_t n = 0;
};

template <class M>
Line frame_of(const M& m, uint8_t seq) {
  uint8_t p[M::kPayloadBytes > 0 ? M::kPayloadBytes : 1] = {};
  eelproto::pack(m, p);
  Line l;
  l.n = encode_frame(static_cast<uint8_t>(M::kId), seq, p, M::kPayloadBytes, l.bytes,
                     sizeof l.bytes);
  return l;
}

double g_t_us = 0.0;
void emit(const Line& l) {
  printf("%.1f", g_t_us);
  for (size_t i = 0; i < l.n; ++i) printf(" %02x", l.bytes[i]);
  printf("\n");
  g_t_us += kByteUs * static_cast<double>(l.n);
}

enum Kind { Commands, Queries, Garbage, Corrupted, Echoes, Replays, kKinds };
const char* const kNames[] = {"commands", "queries", "garbage", "corrupted", "echoes", "replays"};

uint8_t g_seq = 0;
eelproto::SetGait gait() {
  return eelproto::SetGait{0.5f, 3.1416f, 1.04f, 0.5f, 1.0f, 2.0f};
}
float small_offset() { return static_cast<float>(static_cast<int>(rnd() % 200) - 100) * 1e-3f; }

Line command() {
  if (rnd() & 1) return frame_of(gait(), g_seq++);
  return frame_of(eelproto::SetOffset{small_offset()}, g_seq++);
}

Line make(Kind k, Line& last) {
  switch (k) {
    case Commands:
      return last = command();
    case Queries: {
      switch (rnd() % 3) {
        case 0: return frame_of(eelproto::GetStatus{}, g_seq++);
        case 1: return frame_of(eelproto::GetSetting{static_cast<uint8_t>(1 + rnd() % 17), 0},
                             g_seq++);
        default: return frame_of(eelproto::Hello{}, g_seq++);
      }
    }
    case Garbage: {
      Line l;
      l.n = 8 + rnd() % 50;
      for (size_t i = 0; i < l.n; ++i) {
        l.bytes[i] = static_cast<uint8_t>(rnd());
        if (rnd() % 64 == 0) l.bytes[i] = 0;
      }
      return l;
    }
    case Corrupted: {
      Line l = command();
      const size_t at = rnd() % (l.n - 1);  // not the delimiter
      l.bytes[at] ^= static_cast<uint8_t>(1 + rnd() % 255);
      return l;
    }
    case Echoes: {
      if (rnd() & 1) {
        eelproto::Telemetry t{};
        t.time_us = rnd();
        t.state = 1;
        for (int j = 0; j < eelproto::kNJoints; ++j) t.alpha_rad[j] = small_offset();
        return frame_of(t, static_cast<uint8_t>(rnd()));
      }
      eelproto::Status s{};
      s.time_us = rnd();
      s.battery_v = 7.4f;
      return frame_of(s, static_cast<uint8_t>(rnd()));
    }
    case Replays:
    default:
      if (last.n == 0) last = command();
      return last;
  }
}
}  // namespace

int main(int argc, char** argv) {
  const bool mixed = argc >= 2 && strcmp(argv[1], "mixed") == 0;
  int kind = -1;
  for (int k = 0; argc >= 2 && k < kKinds; ++k) {
    if (strcmp(argv[1], kNames[k]) == 0) kind = k;
  }
  const long duration_ms = argc >= 3 ? strtol(argv[2], nullptr, 10) : 0;
  if ((kind < 0 && !mixed) || duration_ms <= 0 || argc > 4) {
    fprintf(stderr,
            "usage: flood commands|queries|garbage|corrupted|echoes|replays|mixed DURATION_MS "
            "[SEED]\n");
    return 2;
  }
  g_rng = argc == 4 ? strtoull(argv[3], nullptr, 10) * 0x9E3779B97F4A7C15ULL + 1 : 1;
  // The session: Hello, the gait, a save of the settings (written a byte a loop pass while the
  // flood runs: the stack and the timing include it), Start.
  g_t_us = 100000;
  emit(frame_of(eelproto::Hello{}, g_seq++));
  emit(frame_of(gait(), g_seq++));
  emit(frame_of(eelproto::SaveSettings{}, g_seq++));
  emit(frame_of(eelproto::Start{}, g_seq++));
  g_t_us = kFloodStartUs;
  double next_keep_alive = kFloodStartUs;
  Line last;
  const double end_us = static_cast<double>(duration_ms) * 1000.0;
  while (g_t_us < end_us) {
    if (g_t_us >= next_keep_alive) {
      // After garbage the line may be mid-"frame": a delimiter first lets the keep-alive through.
      Line keep;
      keep.bytes[0] = 0;
      const Line body = frame_of(eelproto::SetOffset{small_offset()}, g_seq++);
      memcpy(keep.bytes + 1, body.bytes, body.n);
      keep.n = body.n + 1;
      emit(keep);
      if (kind == Replays) last = keep;
      next_keep_alive += kKeepAliveUs;
      continue;
    }
    emit(make(static_cast<Kind>(mixed ? rnd() % kKinds : static_cast<uint32_t>(kind)), last));
  }
  return 0;
}
