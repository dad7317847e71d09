// The eel-like gait (docs/model.md section 4): alpha_j(t) = A_j sin(phi(t) + (j-1) beta) + gamma,
// A_j = A (N-j)/(N+1), j = 1..N-1, where phi is the accumulated phase (phi = omega t while omega is
// constant, as in the twin's eelsim.control.gait_reference).
//
// No change of a parameter makes a reference jump (unless its rate is set to 0 = no limit):
// - omega changes the rate of the phase, never the phase itself;
// - A, beta and the offset gamma slew at their rate limits.
// The phase is an unsigned 64-bit fixed-point fraction of a cycle (2^64 = 2 pi) advanced from integer
// microseconds. Modular arithmetic wraps it for free and it does not drift: after an hour it is as
// exact as after a second (a float32 phase accumulated every 10 ms would be off by ~0.1 rad).
#pragma once
#include <stdint.h>
#include "config.h"

struct GaitTargets {
  float amplitude_rad;
  float omega_rad_s;
  float beta_rad;
  float offset_rad;
};

struct GaitRates {
  float amplitude_rad_s;  // 0 = no limit
  float beta_rad_s;
  float offset_rad_s;
};

class Gait {
 public:
  // Straight and still: amplitude and offset 0, phase 0. `now_us` becomes the time origin.
  void reset(uint32_t now_us);
  // The references at `now_us` (the one costly call: ~1.3 ms on the AVR): advance the phase, slew
  // A, beta and gamma towards their targets over the time since the last update, then cap the
  // amplitude and |gamma| at `cap_rad` (the link-loss envelope). Returns whether the cap bound.
  bool update(uint32_t now_us, float cap_rad);
  // Change targets at `now_us` (cheap: nothing is computed until the next update). A new omega
  // applies from now_us on: the next update first advances the phase at the old rate to then.
  void set_targets(const GaitTargets& t, uint32_t now_us);
  void set_rates(const GaitRates& r) { rates_ = r; }
  // Phase back to 0 with `now_us` as its origin (the twin's t = 0), so that the next update
  // advances it by the time since now, not since the previous update. Only when the amplitude is
  // 0, so nothing jumps; returns whether it restarted.
  bool restart_phase(uint32_t now_us);

  // References after the last update, clamped to +-cfg::kJointLimitRad (a clamped joint's rate is 0).
  const float* alpha_rad() const { return alpha_rad_; }
  const float* alpha_dot_rad_s() const { return alpha_dot_rad_s_; }
  float amplitude_rad() const { return amplitude_rad_; }
  float beta_rad() const { return beta_rad_; }
  float offset_rad() const { return offset_rad_; }
  const GaitTargets& targets() const { return target_; }
  const GaitRates& rates() const { return rates_; }
  // Phase of joint 1 in [-pi, pi).
  float phase_rad() const;
  // Updates computed since reset (wraps): tests count them against the control updates.
  uint16_t updates() const { return updates_; }

 private:
  void advance_phase(uint32_t now_us);
  void compute_references();

  uint64_t phase_q_ = 0;           // fraction of a cycle, 2^64 = one cycle
  uint64_t step_q_per_us_ = 0;     // phase increment per microsecond (from omega)
  uint32_t phase_us_ = 0;          // time the phase was advanced to
  uint32_t last_us_ = 0;           // time of the last update (the slews' step)
  uint32_t omega_set_us_ = 0;      // when a new omega was set, if omega_pending_
  bool omega_pending_ = false;     // step_q_per_us_ is not yet target_.omega_rad_s's
  uint16_t updates_ = 0;
  GaitTargets target_{};
  GaitRates rates_{};
  float amplitude_rad_ = 0.0f;
  float beta_rad_ = 0.0f;
  // sin and cos of beta_rad_ as last computed: beta changes only while it slews to a new target,
  // so most updates skip two of the four trig calls (~3400 cycles on the AVR).
  float trig_beta_rad_ = 0.0f;
  float sin_beta_ = 0.0f;
  float cos_beta_ = 1.0f;
  float offset_rad_ = 0.0f;
  float alpha_rad_[cfg::kJoints] = {};
  float alpha_dot_rad_s_[cfg::kJoints] = {};
};
