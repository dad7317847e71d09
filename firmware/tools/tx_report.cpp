// tx_report: what the robot sent in one tools/eel_avrsim run, read from its --uart-out file
// ("T_US HEX" a byte a line), for `make bench` (docs/firmware.md, "Link": replies first). Prints
//
//   frames out: N valid, B bad; replies: A acks, R refusals, V versions, S settings, T statuses
//   telemetry: N frames, longest gap G ms (robot time), tx_dropped D (last Status)
//
// The Status frames are counted with the replies: the output does not tell a periodic Status from
// the one a GetStatus asked for. tx_dropped (replies the robot had no room to queue) is read from
// the last Status; "?" when none came.
//
//   tx_report UART_OUT_FILE
#include <inttypes.h>
#include <stdint.h>
#include <stdio.h>

#include "frame_codec.h"
#include "message_codec.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    fprintf(stderr, "usage: tx_report UART_OUT_FILE\n");
    return 2;
  }
  FILE* in = fopen(argv[1], "r");
  if (in == nullptr) {
    fprintf(stderr, "tx_report: cannot read %s\n", argv[1]);
    return 2;
  }
  FrameDecoder decoder;
  LinkCounters bad{};
  uint32_t valid = 0, acks = 0, refusals = 0, versions = 0, settings = 0, statuses = 0;
  uint32_t telemetry = 0, last_telemetry_us = 0, longest_gap_us = 0;
  long tx_dropped = -1;
  double t_us = 0.0;
  unsigned byte = 0;
  while (fscanf(in, "%lf %x", &t_us, &byte) == 2) {
    if (!decoder.push(static_cast<uint8_t>(byte), bad)) continue;
    ++valid;
    const Frame& f = decoder.frame();
    switch (static_cast<eelproto::MsgId>(f.msg_id)) {
      case eelproto::MsgId::Ack: ++acks; break;
      case eelproto::MsgId::Refuse: ++refusals; break;
      case eelproto::MsgId::Version: ++versions; break;
      case eelproto::MsgId::Setting: ++settings; break;
      case eelproto::MsgId::Status: {
        ++statuses;
        eelproto::Status s;
        eelproto::unpack(s, f.payload);
        tx_dropped = s.tx_dropped;
        break;
      }
      case eelproto::MsgId::Telemetry: {
        eelproto::Telemetry m;
        eelproto::unpack(m, f.payload);
        const uint32_t gap = m.time_us - last_telemetry_us;
        if (telemetry > 0 && gap > longest_gap_us) longest_gap_us = gap;
        last_telemetry_us = m.time_us;
        ++telemetry;
        break;
      }
      default: break;
    }
  }
  fclose(in);
  printf("frames out: %" PRIu32 " valid, %u bad; replies: %" PRIu32 " acks, %" PRIu32
         " refusals, %" PRIu32 " versions, %" PRIu32 " settings, %" PRIu32 " statuses\n",
         valid, static_cast<unsigned>(bad.bad_total()), acks, refusals, versions,
         settings, statuses);
  printf("telemetry: %" PRIu32 " frames, longest gap %.1f ms (robot time), tx_dropped ", telemetry,
         longest_gap_us / 1000.0);
  if (tx_dropped < 0) {
    printf("? (no Status)\n");
  } else {
    printf("%ld (last Status)\n", tx_dropped);
  }
  return 0;
}
