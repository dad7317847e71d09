#include "gait.h"

#include <math.h>

#include "rate_limit.h"
#include "time_util.h"

namespace {
// 2^64 / (2 pi 1e6): phase increments per microsecond per rad/s.
constexpr double kStepPerRadS = 18446744073709551616.0 / (6.283185307179586 * 1.0e6);
// 2 pi / 2^32: radians per unit of the phase's top 32 bits.
constexpr float kRadPerTop32 = 1.4629180792671596e-09f;
// A_j / A = (N - j) / (N + 1), j = 1..N-1: a table computed by the compiler, because a float
// division costs the AVR ~500 cycles per joint.
struct AmplitudeRatios {
  float of_joint[cfg::kJoints];
  constexpr AmplitudeRatios() : of_joint() {
    for (uint8_t i = 0; i < cfg::kJoints; ++i) {  // joint j = i + 1
      of_joint[i] = static_cast<float>(cfg::kLinks - (i + 1)) / static_cast<float>(cfg::kLinks + 1);
    }
  }
};
constexpr AmplitudeRatios kAmplitudeRatio;

// Phase increments per microsecond at omega. On the AVR double is float: omega then carries a
// relative error of 6e-8 (0.2 ms an hour).
uint64_t phase_step(float omega_rad_s) {
  return static_cast<uint64_t>(static_cast<double>(omega_rad_s) * kStepPerRadS);
}

float clamp_joint(float v) {
  if (v > cfg::kJointLimitRad) return cfg::kJointLimitRad;
  if (v < -cfg::kJointLimitRad) return -cfg::kJointLimitRad;
  return v;
}
}  // namespace

void Gait::reset(uint32_t now_us) {
  step_q_per_us_ = phase_step(target_.omega_rad_s);
  omega_pending_ = false;
  phase_q_ = 0;
  phase_us_ = now_us;
  last_us_ = now_us;
  updates_ = 0;
  amplitude_rad_ = 0.0f;
  offset_rad_ = 0.0f;
  beta_rad_ = target_.beta_rad;
  compute_references();
}

void Gait::set_targets(const GaitTargets& t, uint32_t now_us) {
  if (t.omega_rad_s != target_.omega_rad_s && !omega_pending_) {
    omega_set_us_ = now_us;  // the first change since the last update: the old rate holds to here
    omega_pending_ = true;
  }
  target_ = t;
}

bool Gait::restart_phase(uint32_t now_us) {
  if (amplitude_rad_ != 0.0f) return false;
  phase_q_ = 0;
  phase_us_ = now_us;
  if (omega_pending_) omega_set_us_ = now_us;  // a new omega counts from the restart
  return true;
}

void Gait::advance_phase(uint32_t now_us) {
  phase_q_ += step_q_per_us_ * elapsed_us(now_us, phase_us_);  // wraps modulo one cycle, by design
  phase_us_ = now_us;
}

bool Gait::update(uint32_t now_us, float cap_rad) {
  if (omega_pending_) {
    advance_phase(omega_set_us_);
    step_q_per_us_ = phase_step(target_.omega_rad_s);
    omega_pending_ = false;
  }
  advance_phase(now_us);
  const float dt_s = static_cast<float>(elapsed_us(now_us, last_us_)) * 1e-6f;
  last_us_ = now_us;
  amplitude_rad_ = slew_towards(amplitude_rad_, target_.amplitude_rad, rates_.amplitude_rad_s, dt_s);
  beta_rad_ = slew_towards(beta_rad_, target_.beta_rad, rates_.beta_rad_s, dt_s);
  offset_rad_ = slew_towards(offset_rad_, target_.offset_rad, rates_.offset_rad_s, dt_s);
  // The cap moves the present values themselves, so that a cap lifted again (the link is back)
  // lets them slew up from where they are: nothing jumps unless its rate is 0 (no limit).
  bool capped = false;
  if (amplitude_rad_ > cap_rad) {
    amplitude_rad_ = cap_rad;
    capped = true;
  }
  if (offset_rad_ > cap_rad || offset_rad_ < -cap_rad) {
    offset_rad_ = offset_rad_ > 0.0f ? cap_rad : -cap_rad;
    capped = true;
  }
  compute_references();
  ++updates_;
  return capped;
}

float Gait::phase_rad() const {
  return static_cast<float>(static_cast<int32_t>(static_cast<uint32_t>(phase_q_ >> 32))) *
         kRadPerTop32;
}

void Gait::compute_references() {
  // sin/cos of phi + (j-1) beta by rotating (sin phi, cos phi) by beta: 4 trig calls instead of 10,
  // which matters on an AVR without an FPU (about 1700 cycles each), and only 2 while beta holds
  // still. Four rotations add a few ulp.
  const float phase = phase_rad();
  float s = sinf(phase);
  float c = cosf(phase);
  if (beta_rad_ != trig_beta_rad_) {
    trig_beta_rad_ = beta_rad_;
    sin_beta_ = sinf(beta_rad_);
    cos_beta_ = cosf(beta_rad_);
  }
  const float sb = sin_beta_;
  const float cb = cos_beta_;
  const float omega = target_.omega_rad_s;
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    const float amp = amplitude_rad_ * kAmplitudeRatio.of_joint[j];
    const float raw = amp * s + offset_rad_;
    alpha_rad_[j] = clamp_joint(raw);
    // Like the twin, the offset counts as piecewise constant: it adds nothing to the rate.
    alpha_dot_rad_s_[j] = (raw == alpha_rad_[j]) ? amp * omega * c : 0.0f;
    const float s_next = s * cb + c * sb;
    c = c * cb - s * sb;
    s = s_next;
  }
}
