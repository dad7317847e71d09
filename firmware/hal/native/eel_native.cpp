// The extern "C" face of the native build: an instance is the robot's core plus the native board,
// with the state that survives a reset (the EEPROM, the RAM-kept reset count) beside them.
#include "eel_native.h"

#include <new>
#include <string.h>

#include "app.h"
#include "joint_loop.h"
#include "settings_codec.h"

struct EelFw {
  Robot robot;
  Hal hal;
  uint8_t eeprom[kEepromBytes];
  ResetRecord reset_record;
  uint32_t control_period_us;
};

static_assert(EEL_JOINTS == cfg::kJoints,
              "eel_native.h is stale: run python protocol/generate.py (its EEL_JOINTS is generated)");
static_assert(EEL_BATTERY_INPUT == cfg::kBatteryInput, "eel_native.h: the battery input moved");
static_assert(EEL_EEPROM_BYTES == kEepromBytes, "eel_native.h: the EEPROM size changed");

namespace {
// 7.4 V / 3.2 (the default divider) = 2.31 V at the pin: counts = V * 1024 / 5 V.
constexpr uint16_t kChargedBatteryCounts = 474;

void boot(EelFw* fw, uint32_t now_us, uint8_t reset_flags) {
  const Hal old = fw->hal;
  fw->hal = Hal();
  fw->hal.eeprom = fw->eeprom;
  fw->hal.eeprom_failing = old.eeprom_failing;  // the hardware stays as it was
  for (uint8_t i = 0; i < cfg::kAdcInputs; ++i) fw->hal.adc[i] = old.adc[i];
  const BootInfo info{reset_flags, count_reset(fw->reset_record, reset_flags), false};
  uint8_t eeprom[kSettingsEepromBytes];
  fw->hal.eeprom_load(kSettingsEepromAddress, eeprom, sizeof eeprom);
  fw->robot.reset(now_us, info, eeprom);
  fw->robot.set_control_period_us(fw->control_period_us);
  fw->hal.servo_write_us(fw->robot.pulse_us());
}
}  // namespace

extern "C" {

uint32_t eel_abi_version(void) { return EEL_ABI_VERSION; }

uint16_t eel_schema_hash(void) { return eelproto::kSchemaHash; }

EelFw* eel_create(uint32_t now_us) {
  EelFw* fw = new (std::nothrow) EelFw();
  if (fw != nullptr) {
    // A robot that has been set up: the defaults saved in slot 0 (a blank EEPROM would leave
    // Start refused until the host acknowledged the defaults), and a charged 2S battery (7.4 V)
    // behind the default divider, so that the default low-voltage stop sees a healthy battery.
    memset(fw->eeprom, 0xFF, sizeof fw->eeprom);
    settings_to_image(eelproto::settings_defaults(), fw->eeprom + settings_slot_address(0), 1);
    fw->hal.adc[cfg::kBatteryInput] = kChargedBatteryCounts;
    eel_reset(fw, now_us);
  }
  return fw;
}

void eel_destroy(EelFw* fw) { delete fw; }

void eel_reset(EelFw* fw, uint32_t now_us) {
  fw->control_period_us = cfg::kControlPeriodUs;
  boot(fw, now_us, static_cast<uint8_t>(eelproto::ResetFlags::PowerOn));
}

void eel_reboot(EelFw* fw, uint32_t now_us, uint8_t reset_flags) {
  fw->control_period_us = cfg::kControlPeriodUs;
  const uint8_t power_on = static_cast<uint8_t>(eelproto::ResetFlags::PowerOn);
  boot(fw, now_us, static_cast<uint8_t>(reset_flags & ~power_on));
}

void eel_set_control_period_us(EelFw* fw, uint32_t period_us) {
  fw->control_period_us = period_us;
  fw->robot.set_control_period_us(period_us);
}

size_t eel_feed(EelFw* fw, const uint8_t* data, size_t n) {
  size_t i = 0;
  while (i < n && fw->hal.rx.push(data[i])) ++i;
  return i;
}

size_t eel_take(EelFw* fw, uint8_t* out, size_t cap) {
  size_t i = 0;
  while (i < cap && !fw->hal.tx.empty()) out[i++] = fw->hal.tx.pop();
  return i;
}

void eel_set_uart_tx_stalled(EelFw* fw, int stalled) { fw->hal.tx_stalled = stalled != 0; }

void eel_tick(EelFw* fw, uint32_t now_us, const float* phi_rad, const float* phi_dot_rad_s,
              EelOutputs* out) {
  const uint32_t edges = fw->hal.busy_edges;
  app_tick(fw->robot, fw->hal, now_us, kLockstepTick);
  if (out == nullptr) return;
  const float zeros[cfg::kJoints] = {};
  fw->robot.joint_torques(phi_rad ? phi_rad : zeros, phi_dot_rad_s ? phi_dot_rad_s : zeros,
                          out->torque_nm);
  const Gait& g = fw->robot.gait();
  const JointLoop& joints = fw->robot.joints();
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    out->alpha_rad[j] = g.alpha_rad()[j];
    out->alpha_dot_rad_s[j] = g.alpha_dot_rad_s()[j];
    out->pulse_us[j] = fw->hal.servo_us[j];
    out->phi_measured_rad[j] = joints.phi_rad()[j];
  }
  out->control_ran = fw->hal.busy_edges != edges ? 1 : 0;
  out->measured = joints.measured() ? 1 : 0;
}

void eel_pass(EelFw* fw, uint32_t now_us) { app_tick(fw->robot, fw->hal, now_us, kRobotPass); }

void eel_status(const EelFw* fw, EelStatus* out) {
  const Robot& r = fw->robot;
  const Gait& g = r.gait();
  const LinkCounters& c = r.counters();
  const eelproto::Settings& s = r.settings();
  out->state = static_cast<uint8_t>(r.state());
  out->flags = r.flags();
  out->settings_source = static_cast<uint8_t>(r.settings_source());
  out->reset_flags = r.boot().reset_flags;
  out->amplitude_rad = g.amplitude_rad();
  out->beta_rad = g.beta_rad();
  out->offset_rad = g.offset_rad();
  out->phase_rad = g.phase_rad();
  out->target_amplitude_rad = g.targets().amplitude_rad;
  out->target_omega_rad_s = g.targets().omega_rad_s;
  out->target_beta_rad = g.targets().beta_rad;
  out->target_offset_rad = g.targets().offset_rad;
  out->kp_nm_per_rad = s.kp_nm_per_rad;
  out->kd_nms_per_rad = s.kd_nms_per_rad;
  out->torque_limit_nm = s.torque_limit_nm;
  out->battery_v = r.battery().volts();
  out->last_valid_rx_us = r.watchdog().last_valid_us();
  out->watchdog_kicks = fw->hal.watchdog_kicks;
  out->frames_ok = c.frames_ok;
  out->bad_cobs = c.bad_cobs;
  out->bad_short = c.bad_short;
  out->bad_oversize = c.bad_oversize;
  out->bad_crc = c.bad_crc;
  out->bad_schema = c.bad_schema;
  out->bad_unknown_id = c.bad_unknown_id;
  out->bad_length = c.bad_length;
  out->bad_crc32 = c.bad_crc32;
  out->bad_direction = c.bad_direction;
  out->duplicates = c.duplicates;
  out->lost = c.lost;
  out->tx_dropped = c.tx_dropped;
  out->frames_bad = c.bad_total();
  out->resets = r.boot().resets;
  out->control_updates = r.control_updates();
  out->gait_updates = g.updates();
  out->control_late_max_us = r.control_late_max_us();
}

int eel_set_adc(EelFw* fw, uint8_t input, uint16_t counts) {
  if (input >= cfg::kAdcInputs || counts > 1023) return -1;
  fw->hal.adc[input] = counts;
  return 0;
}

void eel_set_joint_angles(EelFw* fw, const float* phi_rad) {
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    fw->hal.adc[j] = joint_adc_counts(fw->robot.settings(), j, phi_rad[j]);
  }
}

size_t eel_eeprom_read(const EelFw* fw, uint16_t address, uint8_t* out, size_t n) {
  size_t i = 0;
  for (; i < n && address + i < kEepromBytes; ++i) out[i] = fw->eeprom[address + i];
  return i;
}

size_t eel_eeprom_write(EelFw* fw, uint16_t address, const uint8_t* data, size_t n) {
  size_t i = 0;
  for (; i < n && address + i < kEepromBytes; ++i) fw->eeprom[address + i] = data[i];
  return i;
}

void eel_set_eeprom_failing(EelFw* fw, int failing) { fw->hal.eeprom_failing = failing != 0; }

}  // extern "C"
