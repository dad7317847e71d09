// Joint PD law (docs/model.md section 4): u = kp (alpha - phi) + kd (alpha_dot - phi_dot),
// clamped to +-torque_limit. On the robot the hobby servos close this loop themselves on the
// position reference; the firmware's own PD drives the simulated plant in the native build.
#pragma once
#include <stdint.h>

struct PdGains {
  float kp_nm_per_rad;
  float kd_nms_per_rad;
  float torque_limit_nm;
};

float pd_torque_nm(const PdGains& g, float alpha_rad, float alpha_dot_rad_s, float phi_rad,
                   float phi_dot_rad_s);

// The law for n joints at once.
void pd_torques_nm(const PdGains& g, const float* alpha_rad, const float* alpha_dot_rad_s,
                   const float* phi_rad, const float* phi_dot_rad_s, float* torque_nm, uint8_t n);
