#include "joint_loop.h"

#include "pd.h"
#include "servo_map.h"

namespace {
// The rate estimate is the mean of the last difference quotient and the previous estimate (a
// first-order filter): differencing a 10-bit reading every 10 ms turns one count (~8 mrad) into
// ~0.8 rad/s of noise, which the filter halves.
constexpr float kRateFilter = 0.5f;
constexpr float kAdcMaxCounts = 1023.0f;

float clamp_joint(float v) {
  if (v > cfg::kJointLimitRad) return cfg::kJointLimitRad;
  if (v < -cfg::kJointLimitRad) return -cfg::kJointLimitRad;
  return v;
}
}  // namespace

uint16_t joint_adc_counts(const eelproto::Settings& s, uint8_t j, float angle_rad) {
  const float rad = s.reversed[j] ? -angle_rad : angle_rad;
  const float counts = static_cast<float>(s.adc_centre[j]) + rad * s.adc_counts_per_rad[j];
  if (!(counts > 0.0f)) return 0;  // NaN too
  if (counts >= kAdcMaxCounts) return 1023;
  return static_cast<uint16_t>(counts + 0.5f);
}

void JointLoop::configure(const eelproto::Settings& s) {
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    const float scale = 1.0f / s.adc_counts_per_rad[j];
    rad_per_count_[j] = s.reversed[j] ? -scale : scale;
  }
  per_stiffness_ = 1.0f / s.servo_stiffness_nm_per_rad;
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
  // The PD in radians of servo command: u / k_s = (kp / k_s) e + (kd / k_s) e_dot, clamped to
  // limit / k_s. Three products an update instead of one a joint; one division, for the rate.
  const float per_s = (feedback && measured_ && dt_us > 0) ? 1.0e6f / static_cast<float>(dt_us) : 0.0f;
  const PdGains g{s.kp_nm_per_rad * per_stiffness_, s.kd_nms_per_rad * per_stiffness_,
                  s.torque_limit_nm * per_stiffness_};
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    float command = alpha_rad[j];
    if (feedback) {
      const int16_t from_centre = static_cast<int16_t>(adc_counts[j] - s.adc_centre[j]);
      const float phi = static_cast<float>(from_centre) * rad_per_count_[j];
      phi_dot_rad_s_[j] = kRateFilter * (phi_dot_rad_s_[j] + (phi - phi_rad_[j]) * per_s);
      phi_rad_[j] = phi;
      command = clamp_joint(phi + pd_torque_nm(g, alpha_rad[j], alpha_dot_rad_s[j], phi,
                                               phi_dot_rad_s_[j]));
    }
    pulse_us_[j] = servo_pulse_us(s.trim_us[j], s.reversed[j] != 0, s.servo_us_per_rad, command);
  }
  if (!feedback && measured_) reset();
  measured_ = feedback;
}
