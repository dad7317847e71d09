#include <math.h>

#include "check.h"
#include "config.h"
#include "servo_map.h"

TEST(straight_joint_gives_the_centre_pulse_plus_its_trim) {
  CHECK_EQ(servo_pulse_us(0, false, 636.6f, 0.0f), 1500);
  CHECK_EQ(servo_pulse_us(-37, false, 636.6f, 0.0f), 1463);
  CHECK_EQ(servo_pulse_us(25, true, 636.6f, 0.0f), 1525);
}

TEST(pulse_grows_by_the_calibrated_width_per_radian_and_the_other_way_reversed) {
  CHECK_EQ(servo_pulse_us(0, false, 636.6f, 1.0f), 2137);
  CHECK_EQ(servo_pulse_us(0, false, 636.6f, -1.0f), 863);
  CHECK_EQ(servo_pulse_us(0, true, 636.6f, 1.0f), 863);
  CHECK_EQ(servo_pulse_us(100, true, 500.0f, -0.5f), 1850);
}

TEST(pulse_is_clamped_to_what_any_hobby_servo_accepts) {
  CHECK_EQ(servo_pulse_us(0, false, 636.6f, 5.0f), kServoMaxUs);
  CHECK_EQ(servo_pulse_us(0, false, 636.6f, -5.0f), kServoMinUs);
  CHECK_EQ(servo_pulse_us(0, false, 636.6f, 1e30f), kServoMaxUs);
  CHECK_EQ(servo_pulse_us(500, false, 2000.0f, 1.2f), kServoMaxUs);
}

TEST(nan_angle_gives_the_trimmed_centre_pulse) {
  CHECK_EQ(servo_pulse_us(0, false, 636.6f, nanf("")), 1500);
  CHECK_EQ(servo_pulse_us(-20, false, 636.6f, nanf("")), 1480);
}

TEST(joint_limit_with_the_default_calibration_stays_inside_the_servo_range) {
  CHECK(servo_pulse_us(0, false, 636.6f, cfg::kJointLimitRad) < kServoMaxUs);
  CHECK(servo_pulse_us(0, false, 636.6f, -cfg::kJointLimitRad) > kServoMinUs);
}
