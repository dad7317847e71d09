#include "pd.h"

float pd_torque_nm(const PdGains& g, float alpha_rad, float alpha_dot_rad_s, float phi_rad,
                   float phi_dot_rad_s) {
  const float u = g.kp_nm_per_rad * (alpha_rad - phi_rad) +
                  g.kd_nms_per_rad * (alpha_dot_rad_s - phi_dot_rad_s);
  if (u > g.torque_limit_nm) return g.torque_limit_nm;
  if (u < -g.torque_limit_nm) return -g.torque_limit_nm;
  return u;  // NaN from a NaN measurement passes through: the caller's plant should see it
}

void pd_torques_nm(const PdGains& g, const float* alpha_rad, const float* alpha_dot_rad_s,
                   const float* phi_rad, const float* phi_dot_rad_s, float* torque_nm, uint8_t n) {
  for (uint8_t j = 0; j < n; ++j) {
    torque_nm[j] = pd_torque_nm(g, alpha_rad[j], alpha_dot_rad_s[j], phi_rad[j], phi_dot_rad_s[j]);
  }
}
