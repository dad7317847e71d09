#include <math.h>

#include "check.h"
#include "gait.h"

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr float kNoCap = 1e9f;  // the link-loss envelope wide open

// The gait of docs/model.md section 4 in double precision:
// alpha_j = A (N-j)/(N+1) sin(omega t + (j-1) beta) + gamma.
double model_alpha(int j0, double t_s, double a, double omega, double beta, double gamma) {
  const double n = cfg::kLinks;
  return a * (n - (j0 + 1)) / (n + 1.0) * sin(omega * t_s + j0 * beta) + gamma;
}

Gait started_gait(uint32_t t0_us, GaitTargets t, GaitRates r = GaitRates{0, 0, 0}) {
  Gait g;
  g.set_targets(t, t0_us);
  g.set_rates(r);
  g.reset(t0_us);
  g.update(t0_us, kNoCap);
  return g;
}

float max_step(const float* a, const float* b) {
  float m = 0.0f;
  for (int j = 0; j < cfg::kJoints; ++j) m = fmaxf(m, fabsf(a[j] - b[j]));
  return m;
}
}  // namespace

TEST(gait_equals_the_model_formula_at_the_start_of_a_run) {
  const GaitTargets t{0.6f, 3.0f, 1.04f, 0.05f};
  Gait g = started_gait(1000, t);
  for (uint32_t k = 0; k <= 500; ++k) {
    const uint32_t now = 1000 + k * 10000;
    g.update(now, kNoCap);
    for (int j = 0; j < cfg::kJoints; ++j) {
      CHECK_NEAR(g.alpha_rad()[j], model_alpha(j, k * 0.01, 0.6f, 3.0f, 1.04f, 0.05f), 2e-6);
    }
  }
}

TEST(gait_rate_equals_the_derivative_of_the_formula) {
  Gait g = started_gait(0, GaitTargets{0.5f, 2.0f, 0.8f, 0.0f});
  g.update(1234567, kNoCap);
  const double t = 1.234567;
  for (int j = 0; j < cfg::kJoints; ++j) {
    const double ratio = (cfg::kLinks - 1.0 - j) / (cfg::kLinks + 1.0);  // (N - j) / (N + 1)
    const double want = 0.5f * ratio * 2.0 * cos(2.0 * t + j * static_cast<double>(0.8f));
    CHECK_NEAR(g.alpha_dot_rad_s()[j], want, 1e-5);
  }
}

TEST(gait_phase_does_not_drift_over_an_hour_of_10ms_updates) {
  const float omega = 4.7f;
  Gait g = started_gait(0, GaitTargets{0.5f, omega, 1.0f, 0.0f});
  uint32_t now = 0;
  for (uint32_t k = 0; k < 360000; ++k) g.update(now += 10000, kNoCap);
  const double t = now * 1e-6;
  const double want = remainder(static_cast<double>(omega) * t, 2.0 * kPi);
  CHECK_NEAR(remainder(g.phase_rad() - want, 2.0 * kPi), 0.0, 2e-6);
}

TEST(gait_is_continuous_across_the_micros_wrap) {
  const uint32_t t0 = 0xFFFFFFFFu - 250000u;  // 0.25 s before the wrap
  Gait g = started_gait(t0, GaitTargets{0.5f, 3.0f, 1.04f, 0.0f});
  for (uint32_t k = 1; k <= 100; ++k) {
    const uint32_t now = t0 + k * 10000u;  // wraps at k = 26
    g.update(now, kNoCap);
    for (int j = 0; j < cfg::kJoints; ++j) CHECK_NEAR(g.alpha_rad()[j], model_alpha(j, k * 0.01, 0.5f, 3.0f, 1.04f, 0.0), 2e-6);
  }
}

TEST(frequency_change_keeps_every_reference_continuous) {
  Gait g = started_gait(0, GaitTargets{0.8f, 2.0f, 1.0f, 0.0f});
  g.update(730000, kNoCap);
  float before[cfg::kJoints];
  for (int j = 0; j < cfg::kJoints; ++j) before[j] = g.alpha_rad()[j];
  g.set_targets(GaitTargets{0.8f, 9.0f, 1.0f, 0.0f}, 730000);
  g.update(730000, kNoCap);  // the same instant: a new omega alone must not move anything
  CHECK(max_step(before, g.alpha_rad()) < 1e-6f);
  g.update(731000, kNoCap);  // 1 ms later at 9 rad/s: |d alpha| <= A_1 omega dt = 0.0052
  CHECK(max_step(before, g.alpha_rad()) < 0.0052f);
}

TEST(amplitude_and_beta_changes_slew_at_their_rate_limits) {
  Gait g = started_gait(0, GaitTargets{0.2f, 3.0f, 0.5f, 0.0f}, GaitRates{0.5f, 1.0f, 2.0f});
  // reset() starts at amplitude 0: ramp up first.
  g.update(1000000, kNoCap);
  CHECK_NEAR(g.amplitude_rad(), 0.2, 1e-6);
  g.set_targets(GaitTargets{1.2f, 3.0f, 1.5f, 0.0f}, 1000000);
  float prev[cfg::kJoints];
  for (int j = 0; j < cfg::kJoints; ++j) prev[j] = g.alpha_rad()[j];
  float worst = 0.0f;
  for (uint32_t now = 1010000; now <= 4000000; now += 10000) {
    g.update(now, kNoCap);
    worst = fmaxf(worst, max_step(prev, g.alpha_rad()));
    for (int j = 0; j < cfg::kJoints; ++j) prev[j] = g.alpha_rad()[j];
    if (now == 1510000) {
      CHECK_NEAR(g.amplitude_rad(), 0.2 + 0.5 * 0.51, 1e-5);
      CHECK_NEAR(g.beta_rad(), 0.5 + 1.0 * 0.51, 1e-5);
    }
  }
  CHECK_NEAR(g.amplitude_rad(), 1.2, 1e-6);
  CHECK_NEAR(g.beta_rad(), 1.5, 1e-6);
  // Per 10 ms step: the oscillation (A_1 omega dt <= 0.026) plus the slew terms; far below a jump.
  CHECK(worst < 0.05f);
}

TEST(offset_is_rate_limited_and_jumps_only_when_the_limit_is_zero) {
  Gait g = started_gait(0, GaitTargets{0.0f, 3.0f, 1.0f, 0.0f}, GaitRates{0.0f, 0.0f, 2.0f});
  g.set_targets(GaitTargets{0.0f, 3.0f, 1.0f, 0.5f}, 0);
  g.update(100000, kNoCap);
  CHECK_NEAR(g.offset_rad(), 0.2, 1e-6);
  g.update(300000, kNoCap);
  CHECK_NEAR(g.offset_rad(), 0.5, 1e-6);
  g.set_rates(GaitRates{0.0f, 0.0f, 0.0f});
  g.set_targets(GaitTargets{0.0f, 3.0f, 1.0f, -0.3f}, 300000);
  g.update(300001, kNoCap);
  CHECK_EQ(g.offset_rad(), -0.3f);  // the twin's zero-order hold
}

TEST(references_are_clamped_to_the_joint_limit_with_zero_rate) {
  Gait g = started_gait(0, GaitTargets{1.5f, 1.0f, 0.0f, 1.0f});
  g.update(1570796, kNoCap);  // phase pi/2: joint 1 wants 1.5*5/7 + 1 = 2.07 rad
  CHECK_EQ(g.alpha_rad()[0], cfg::kJointLimitRad);
  CHECK_EQ(g.alpha_dot_rad_s()[0], 0.0f);
  for (int j = 0; j < cfg::kJoints; ++j) CHECK(fabsf(g.alpha_rad()[j]) <= cfg::kJointLimitRad);
}

TEST(phase_restarts_only_when_the_body_is_straight) {
  Gait g = started_gait(0, GaitTargets{0.5f, 3.0f, 1.0f, 0.0f});
  g.update(500000, kNoCap);
  CHECK(!g.restart_phase(500000));
  g.set_targets(GaitTargets{0.0f, 3.0f, 1.0f, 0.0f}, 500000);
  g.update(510000, kNoCap);
  CHECK(g.restart_phase(510000));
  CHECK_EQ(g.phase_rad(), 0.0f);
}

TEST(restarted_phase_counts_from_the_restart_not_from_the_last_update) {
  // Start is handled between two control updates (at 505 ms, after the one at 500 ms): the gait's
  // t = 0 is 505 ms, so at the next update (510 ms) the phase is omega * 5 ms, not omega * 10 ms.
  Gait g = started_gait(0, GaitTargets{0.0f, 3.0f, 1.0f, 0.0f});
  g.update(500000, kNoCap);
  CHECK(g.restart_phase(505000));
  CHECK_EQ(g.phase_rad(), 0.0f);
  g.update(510000, kNoCap);
  CHECK_NEAR(g.phase_rad(), 3.0 * 0.005, 1e-6);
}

TEST(a_new_frequency_applies_from_the_time_it_is_set_not_from_the_last_update) {
  // A command between two control updates only sets the target; the phase runs at the old
  // omega up to that instant and at the new one from it.
  Gait g = started_gait(0, GaitTargets{0.5f, 2.0f, 1.0f, 0.0f});
  g.update(100000, kNoCap);
  g.set_targets(GaitTargets{0.5f, 6.0f, 1.0f, 0.0f}, 104000);
  g.update(110000, kNoCap);
  CHECK_NEAR(g.phase_rad(), 2.0 * 0.104 + 6.0 * 0.006, 2e-6);
}

TEST(the_cap_holds_amplitude_and_offset_and_lifted_they_slew_back_from_where_they_are) {
  Gait g = started_gait(0, GaitTargets{0.8f, 3.0f, 1.0f, -0.4f}, GaitRates{0.5f, 0.0f, 2.0f});
  g.update(2000000, kNoCap);
  CHECK_NEAR(g.amplitude_rad(), 0.8, 1e-6);
  CHECK(g.update(2010000, 0.3f));
  CHECK_EQ(g.amplitude_rad(), 0.3f);
  CHECK_EQ(g.offset_rad(), -0.3f);
  CHECK(g.update(2020000, 0.0f));
  for (int j = 0; j < cfg::kJoints; ++j) CHECK_EQ(g.alpha_rad()[j], 0.0f);
  CHECK(!g.update(2120000, kNoCap));  // lifted: 0.1 s of slewing at 0.5 and 2 rad/s
  CHECK_NEAR(g.amplitude_rad(), 0.05, 1e-6);
  CHECK_NEAR(g.offset_rad(), -0.2, 1e-6);
}

TEST(each_update_is_counted) {
  Gait g = started_gait(0, GaitTargets{0.5f, 3.0f, 1.0f, 0.0f});
  const uint16_t before = g.updates();
  for (uint32_t k = 1; k <= 7; ++k) g.update(k * 10000, kNoCap);
  CHECK_EQ(g.updates(), before + 7);
}
