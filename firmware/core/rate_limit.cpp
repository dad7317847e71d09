#include "rate_limit.h"

float slew_towards(float current, float target, float rate_per_s, float dt_s) {
  if (rate_per_s <= 0.0f) return target;
  const float step = rate_per_s * dt_s;
  if (target > current + step) return current + step;
  if (target < current - step) return current - step;
  return target;
}
