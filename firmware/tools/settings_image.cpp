// settings_image: write the EEPROM image (1024 bytes, erased = 0xFF) that holds the default
// settings with some changed, as the robot's SaveSettings would store them. For the benchmark
// and tests that boot the AVR image in simavr with settings (eel_avrsim --eeprom-in).
//
//   settings_image OUT.bin KEY[.INDEX]=VALUE ...     e.g. 11=1 (joint_feedback on) 1.2=-30
//
// Keys are those of the settings table (docs/firmware.md); the values are checked as SetSetting
// checks them.
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "settings_codec.h"
#include "settings_store.h"

int main(int argc, char** argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: settings_image OUT.bin KEY[.INDEX]=VALUE ...\n");
    return 2;
  }
  eelproto::Settings s = eelproto::settings_defaults();
  for (int i = 2; i < argc; ++i) {
    char* end;
    const long key = strtol(argv[i], &end, 10);
    long index = 0;
    if (*end == '.') index = strtol(end + 1, &end, 10);
    if (*end != '=' || key < 0 || key > 255 || index < 0 || index > 255) {
      fprintf(stderr, "settings_image: %s: expected KEY[.INDEX]=VALUE\n", argv[i]);
      return 2;
    }
    bool changed = false;
    const float value = strtof(end + 1, nullptr);
    const uint8_t why = eelproto::setting_set(s, static_cast<uint8_t>(key),
                                              static_cast<uint8_t>(index), value, changed);
    if (why != 0) {
      fprintf(stderr, "settings_image: %s: refused (RefuseReason %u)\n", argv[i], why);
      return 2;
    }
  }
  uint8_t eeprom[1024];
  memset(eeprom, 0xFF, sizeof eeprom);
  settings_to_image(s, eeprom + settings_slot_address(0), 1);  // slot 1 stays erased
  FILE* f = fopen(argv[1], "wb");
  if (f == nullptr || fwrite(eeprom, 1, sizeof eeprom, f) != sizeof eeprom || fclose(f) != 0) {
    fprintf(stderr, "settings_image: cannot write %s\n", argv[1]);
    return 2;
  }
  return 0;
}
