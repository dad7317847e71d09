// Arduino entry points for the Nano image: the core's main() calls setup() once, then loop().
// The clock is read once per pass and handed down; nothing below reads it again.
#include "app.h"

namespace {
Robot g_robot;
Hal g_hal;
}  // namespace

// The Arduino core declares both with C linkage (in Arduino.h, which app/ does not include).
extern "C" void setup();
extern "C" void loop();

void setup() {
  g_hal.begin();
  uint8_t eeprom[kSettingsEepromBytes];  // both slots
  g_hal.eeprom_load(kSettingsEepromAddress, eeprom, sizeof eeprom);
  g_robot.reset(g_hal.now_us(), g_hal.boot_info(), eeprom);
  g_hal.start_watchdog();
}

void loop() { app_tick(g_robot, g_hal, g_hal.now_us()); }
