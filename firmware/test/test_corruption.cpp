// The command-integrity bench (tools/corruption.h, docs/firmware.md "Command integrity") on a
// short run: the long runs of `make integrity` give the figures.
#include "../tools/corruption.h"
#include "check.h"

TEST(corrupted_commands_never_execute_even_when_the_crc16_misses_every_error) {
  CorruptionBench bench(0.05, 3, /*refresh_crc16=*/true);
  bench.run(20000);
  const CorruptionStats& s = bench.stats();
  CHECK(s.corrupted > 5000);
  CHECK(s.acknowledged > 2000);  // intact commands still run
  // Without the CRC-32 the robot would have run thousands of these ...
  CHECK(s.passed_crc16 > 5000);
  CHECK(s.crc16_only_executed > 2000);
  CHECK(s.stopped_by_crc32 > 2000);
  // ... with it, none.
  CHECK_EQ(s.corrupted_executed, 0u);
}

TEST(an_uncorrupted_stream_is_never_counted_as_corrupted) {
  CorruptionBench bench(0.0, 4, false);
  bench.run(2000);
  const CorruptionStats& s = bench.stats();
  CHECK_EQ(s.corrupted, 0u);
  CHECK_EQ(s.corrupted_executed, 0u);
  CHECK_EQ(s.stopped_by_crc32, 0u);
  CHECK(s.acknowledged > 1000);
}
