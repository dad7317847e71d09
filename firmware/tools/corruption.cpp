// corruption: how often a command corrupted on the air still executes (docs/firmware.md,
// "Command integrity"). Sends FRAMES random valid commands through the robot's own decoder with
// each byte corrupted with probability P, and prints the counts of tools/corruption.h.
//
//   corruption P FRAMES SEED [refresh-crc16]
//
// refresh-crc16 puts a matching CRC-16 on every corrupted frame, as if the CRC-16 missed every
// error: what then stops corrupted commands is the CRC-32 alone (with the range checks).
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "corruption.h"

int main(int argc, char** argv) {
  if (argc < 4 || argc > 5 || (argc == 5 && strcmp(argv[4], "refresh-crc16") != 0)) {
    fprintf(stderr, "usage: corruption P FRAMES SEED [refresh-crc16]\n");
    return 2;
  }
  char* end;
  const double p = strtod(argv[1], &end);
  if (*end != '\0' || !(p >= 0.0 && p < 1.0)) {
    fprintf(stderr, "corruption: P must be a probability in [0, 1), got %s\n", argv[1]);
    return 2;
  }
  const unsigned long long frames = strtoull(argv[2], &end, 10);
  if (*end != '\0' || frames == 0) {
    fprintf(stderr, "corruption: FRAMES must be a positive integer, got %s\n", argv[2]);
    return 2;
  }
  const unsigned long long seed = strtoull(argv[3], &end, 10);
  if (*end != '\0') {
    fprintf(stderr, "corruption: SEED must be an integer, got %s\n", argv[3]);
    return 2;
  }
  CorruptionBench bench(p, seed, argc == 5);
  bench.run(frames);
  const CorruptionStats& s = bench.stats();
  printf("p=%g frames=%llu corrupted=%llu acknowledged=%llu corrupted_executed=%llu "
         "passed_crc16=%llu crc16_only_executed=%llu stopped_by_crc32=%llu%s\n",
         p, static_cast<unsigned long long>(s.frames),
         static_cast<unsigned long long>(s.corrupted),
         static_cast<unsigned long long>(s.acknowledged),
         static_cast<unsigned long long>(s.corrupted_executed),
         static_cast<unsigned long long>(s.passed_crc16),
         static_cast<unsigned long long>(s.crc16_only_executed),
         static_cast<unsigned long long>(s.stopped_by_crc32), argc == 5 ? " (crc16 refreshed)" : "");
  return 0;
}
