// Move a value towards a target by at most rate * dt; a rate of 0 means "no limit" (jump).
#pragma once

// Out of line: the gait slews three values, and one copy of the float code saves the AVR ~400
// bytes of flash.
float slew_towards(float current, float target, float rate_per_s, float dt_s);
