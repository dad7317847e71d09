// The joint servo loop (docs/firmware.md, "Joint loop"): from the gait's references, and with
// analog-feedback servos from the measured joint angles, to one servo pulse per joint.
//
// Without feedback each servo is commanded to its reference alpha_j and closes the position loop
// itself. With feedback (setting joint_feedback) the robot measures phi_j from the servo's
// potentiometer on the ADC, estimates its rate, runs the joint PD of docs/model.md section 4,
// u_j = kp (alpha_j - phi_j) + kd (alpha_dot_j - phi_dot_j) clamped to the torque limit, and
// commands the servo to phi_j + u_j / k_s: a servo whose own loop is a spring of stiffness k_s
// (setting servo_stiffness_nm_per_rad) then pushes with u_j. With kp = k_s and kd = 0 this is the
// feedback-free command alpha_j again.
#pragma once
#include <stdint.h>

#include "config.h"
#include "protocol_gen.h"

class JointLoop {
 public:
  // Forget the measurements (the next update with feedback starts the rate estimate afresh).
  void reset();
  // Take the feedback calibration and servo stiffness from the settings: call after they change.
  // (Their inverses are kept, so that an update divides nothing: a float division costs the AVR
  // ~500 cycles.)
  void configure(const eelproto::Settings& s);
  // One update, dt_us after the previous one. adc_counts: the joints' potentiometer readings,
  // joint 1 first, or nullptr without feedback.
  void update(const eelproto::Settings& s, const float* alpha_rad, const float* alpha_dot_rad_s,
              const uint16_t* adc_counts, uint32_t dt_us);
  const uint16_t* pulse_us() const { return pulse_us_; }
  // Measured angles and rates after the last update with feedback (0 before and without).
  const float* phi_rad() const { return phi_rad_; }
  const float* phi_dot_rad_s() const { return phi_dot_rad_s_; }
  bool measured() const { return measured_; }

 private:
  float phi_rad_[cfg::kJoints] = {};
  float phi_dot_rad_s_[cfg::kJoints] = {};
  float rad_per_count_[cfg::kJoints] = {};  // signed: negative for a reversed servo
  float per_stiffness_ = 0.0f;
  uint16_t pulse_us_[cfg::kJoints] = {};
  bool measured_ = false;
};

// The reading a joint angle gives, rounded and clamped to the ADC's 0..1023 (the native build's
// way of feeding measured angles through the calibration).
uint16_t joint_adc_counts(const eelproto::Settings& s, uint8_t j, float angle_rad);
