#include <math.h>

#include "check.h"
#include "servo_map.h"

TEST(straight_joint_gives_the_centre_pulse) {
  CHECK_EQ(servo_pulse_us(kServoCalibration[0], 0.0f), 1500);
}

TEST(pulse_grows_by_the_calibrated_width_per_radian) {
  const ServoCalibration cal{1500, 636.6f, 500, 2500};
  CHECK_EQ(servo_pulse_us(cal, 1.0f), 2137);
  CHECK_EQ(servo_pulse_us(cal, -1.0f), 863);
}

TEST(pulse_is_clamped_to_the_servo_limits) {
  const ServoCalibration cal{1500, 636.6f, 700, 2300};
  CHECK_EQ(servo_pulse_us(cal, 5.0f), 2300);
  CHECK_EQ(servo_pulse_us(cal, -5.0f), 700);
  CHECK_EQ(servo_pulse_us(cal, 1e30f), 2300);
}

TEST(nan_angle_gives_the_centre_pulse) {
  CHECK_EQ(servo_pulse_us(kServoCalibration[0], nanf("")), 1500);
}

TEST(joint_limit_stays_inside_every_servo_range) {
  for (const ServoCalibration& cal : kServoCalibration) {
    CHECK(servo_pulse_us(cal, cfg::kJointLimitRad) < cal.max_us);
    CHECK(servo_pulse_us(cal, -cfg::kJointLimitRad) > cal.min_us);
  }
}
