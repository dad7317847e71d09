// Move a value towards a target by at most rate * dt; a rate of 0 means "no limit" (jump).
#pragma once

inline float slew_towards(float current, float target, float rate_per_s, float dt_s) {
  if (rate_per_s <= 0.0f) return target;
  const float step = rate_per_s * dt_s;
  if (target > current + step) return current + step;
  if (target < current - step) return current - step;
  return target;
}
