#include "check.h"
#include "pd.h"

TEST(pd_torque_is_kp_times_angle_error_plus_kd_times_rate_error) {
  const PdGains g{2.0f, 0.5f, 100.0f};
  CHECK_NEAR(pd_torque_nm(g, 0.3f, 1.0f, 0.1f, -1.0f), 2.0 * 0.2 + 0.5 * 2.0, 1e-6);
  CHECK_EQ(pd_torque_nm(g, 0.2f, 0.4f, 0.2f, 0.4f), 0.0f);
}

TEST(pd_torque_is_clamped_to_the_torque_limit) {
  const PdGains g{10.0f, 0.0f, 1.26f};
  CHECK_EQ(pd_torque_nm(g, 1.0f, 0.0f, 0.0f, 0.0f), 1.26f);
  CHECK_EQ(pd_torque_nm(g, -1.0f, 0.0f, 0.0f, 0.0f), -1.26f);
}

TEST(pd_torques_apply_the_law_to_every_joint) {
  const PdGains g{1.0f, 0.1f, 5.0f};
  const float a[5] = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f}, ad[5] = {1, 1, 1, 1, 1};
  const float phi[5] = {0, 0, 0, 0, 0}, phid[5] = {0, 0, 0, 0, 0};
  float u[5];
  pd_torques_nm(g, a, ad, phi, phid, u, 5);
  for (int j = 0; j < 5; ++j) CHECK_NEAR(u[j], a[j] + 0.1f, 1e-6);
}
