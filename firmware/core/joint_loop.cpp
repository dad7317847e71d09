#include "joint_loop.h"

#include "pd.h"
#include "servo_map.h"

namespace {
// Weight of the newest rate sample in the filtered rate estimate: differencing a 10-bit reading
// every 10 ms turns one count (~8 mrad) into ~0.8 rad/s, which the filter halves.
constexpr float kRateFilter = 0.5f;
constexpr float kAdcMaxCounts = 1023.0f;

float clamp_joint(float v) {
  if (v > cfg::kJointLimitRad) return cfg::kJointLimitRad;
  if (v < -cfg::kJointLimitRad) return -cfg::kJointLimitRad;
  return v;
}
}  // namespace

float joint_angle_rad(const eelproto::Settings& s, uint8_t j, uint16_t counts) {
  const float rad = (static_cast<float>(counts) - static_cast<float>(s.adc_centre[j])) /
                    s.adc_counts_per_rad[j];
  return s.reversed[j] ? -rad : rad;
}

uint16_t joint_adc_counts(const eelproto::Settings& s, uint8_t j, float angle_rad) {
  const float rad = s.reversed[j] ? -angle_rad : angle_rad;
  const float counts = static_cast<float>(s.adc_centre[j]) + rad * s.adc_counts_per_rad[j];
  if (!(counts > 0.0f)) return 0;  // NaN too
  if (counts >= kAdcMaxCounts) return 1023;
  return static_cast<uint16_t>(counts + 0.5f);
}

void JointLoop::reset() {
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    phi_rad_[j] = 0.0f;
    phi_dot_rad_s_[j] = 0.0f;
  }
  measured_ = false;
}

void JointLoop::update(const eelproto::Settings& s, const float* alpha_rad,
                       const float* alpha_dot_rad_s, const uint16_t* adc_counts, uint32_t dt_us) {
  const bool feedback = adc_counts != nullptr;
  float per_s = 0.0f, per_nm = 0.0f;
  const PdGains g{s.kp_nm_per_rad, s.kd_nms_per_rad, s.torque_limit_nm};
  if (feedback) {
    // Two divisions an update, not one per joint: a float division costs the AVR ~500 cycles.
    per_s = (measured_ && dt_us > 0) ? 1.0e6f / static_cast<float>(dt_us) : 0.0f;
    per_nm = 1.0f / s.servo_stiffness_nm_per_rad;
  }
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    float command = alpha_rad[j];
    if (feedback) {
      const float phi = joint_angle_rad(s, j, adc_counts[j]);
      const float rate = (phi - phi_rad_[j]) * per_s;
      phi_dot_rad_s_[j] += kRateFilter * (rate - phi_dot_rad_s_[j]);
      phi_rad_[j] = phi;
      const float u = pd_torque_nm(g, alpha_rad[j], alpha_dot_rad_s[j], phi, phi_dot_rad_s_[j]);
      command = clamp_joint(phi + u * per_nm);
    }
    pulse_us_[j] = servo_pulse_us(s.trim_us[j], s.reversed[j] != 0, s.servo_us_per_rad, command);
  }
  if (!feedback && measured_) reset();
  measured_ = feedback;
}
