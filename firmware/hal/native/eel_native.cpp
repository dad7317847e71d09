// The extern "C" face of the native build: an instance is the robot's core plus the native board.
#include "eel_native.h"

#include <new>

#include "app.h"

struct EelFw {
  Robot robot;
  Hal hal;
};

static_assert(EEL_JOINTS == cfg::kJoints,
              "eel_native.h is stale: run python protocol/generate.py (its EEL_JOINTS is generated)");

extern "C" {

uint32_t eel_abi_version(void) { return EEL_ABI_VERSION; }

uint16_t eel_schema_hash(void) { return eelproto::kSchemaHash; }

EelFw* eel_create(uint32_t now_us) {
  EelFw* fw = new (std::nothrow) EelFw();
  if (fw != nullptr) eel_reset(fw, now_us);
  return fw;
}

void eel_destroy(EelFw* fw) { delete fw; }

void eel_reset(EelFw* fw, uint32_t now_us) {
  fw->hal = Hal();
  fw->robot.reset(now_us);
  fw->hal.servo_write_us(fw->robot.pulse_us());
}

void eel_set_control_period_us(EelFw* fw, uint32_t period_us) {
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

void eel_tick(EelFw* fw, uint32_t now_us, const float* phi_rad, const float* phi_dot_rad_s,
              EelOutputs* out) {
  const uint32_t edges = fw->hal.busy_edges;
  app_tick(fw->robot, fw->hal, now_us);
  if (out == nullptr) return;
  const float zeros[cfg::kJoints] = {};
  fw->robot.joint_torques(phi_rad ? phi_rad : zeros, phi_dot_rad_s ? phi_dot_rad_s : zeros,
                          out->torque_nm);
  const Gait& g = fw->robot.gait();
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    out->alpha_rad[j] = g.alpha_rad()[j];
    out->alpha_dot_rad_s[j] = g.alpha_dot_rad_s()[j];
    out->pulse_us[j] = fw->hal.servo_us[j];
  }
  out->control_ran = fw->hal.busy_edges != edges ? 1 : 0;
}

void eel_status(const EelFw* fw, EelStatus* out) {
  const Robot& r = fw->robot;
  const Gait& g = r.gait();
  const LinkCounters& c = r.counters();
  out->state = static_cast<uint8_t>(r.state());
  out->amplitude_rad = g.amplitude_rad();
  out->beta_rad = g.beta_rad();
  out->offset_rad = g.offset_rad();
  out->phase_rad = g.phase_rad();
  out->target_amplitude_rad = g.targets().amplitude_rad;
  out->target_omega_rad_s = g.targets().omega_rad_s;
  out->target_beta_rad = g.targets().beta_rad;
  out->target_offset_rad = g.targets().offset_rad;
  out->kp_nm_per_rad = r.gains().kp_nm_per_rad;
  out->kd_nms_per_rad = r.gains().kd_nms_per_rad;
  out->torque_limit_nm = r.gains().torque_limit_nm;
  out->last_valid_rx_us = r.watchdog().last_valid_us();
  out->frames_ok = c.frames_ok;
  out->bad_cobs = c.bad_cobs;
  out->bad_short = c.bad_short;
  out->bad_oversize = c.bad_oversize;
  out->bad_crc = c.bad_crc;
  out->bad_schema = c.bad_schema;
  out->bad_unknown_id = c.bad_unknown_id;
  out->bad_length = c.bad_length;
  out->duplicates = c.duplicates;
  out->lost = c.lost;
  out->tx_dropped = c.tx_dropped;
  out->frames_bad = c.bad_total();
}

}  // extern "C"
