// Build-time constants of the robot and the control stack, in one place.
#pragma once
#include <stdint.h>
#include "protocol_gen.h"

namespace cfg {

// The joint count and the shared periods come from protocol/eelbot.toml (via protocol_gen.h):
// change them there and run `python protocol/generate.py`.
constexpr uint8_t kJoints = eelproto::kNJoints;  // joint 1 (index 0) is the tail joint
constexpr uint8_t kLinks = kJoints + 1;          // N: head, body modules, tail

constexpr uint8_t kFirmwareMajor = 0;
constexpr uint8_t kFirmwareMinor = 2;

// Mechanical range of every joint module; references (and so servo pulses) are clamped to it.
constexpr float kJointLimitRad = 1.2f;

constexpr uint32_t kControlPeriodUs = eelproto::kControlPeriodUs;
constexpr uint32_t kTelemetryPeriodUs = eelproto::kTelemetryPeriodUs;
constexpr uint32_t kStatusPeriodUs = eelproto::kStatusPeriodUs;
constexpr uint32_t kLinkTimeoutUs = eelproto::kLinkTimeoutUs;  // failsafe after this long quiet
constexpr uint32_t kLinkRestUs = eelproto::kLinkRestUs;        // straight after this long quiet
static_assert(kLinkRestUs < kLinkTimeoutUs, "the joints must be straight before FAILSAFE");
// The link-loss envelope closes at this rate (docs/firmware.md, "Failsafe"): an amplitude of
// 1.5 rad (SetGait's largest) starts fading 0.375 s before kLinkRestUs, the default 0.5 rad only
// 0.125 s before. Fast enough to straighten any gait in time; slow enough for hobby servos
// (~5 rad/s unloaded).
constexpr float kFadeRateRadS = 4.0f;
// When straightening (Stop, failsafe, low battery) the amplitude and offset move at least this
// fast, so that a tiny configured slew rate cannot keep the robot undulating for long.
constexpr float kStraightenMinRateRadS = 1.0f;

// Analog inputs the board samples at each control update while the robot asks for them
// (Robot::wants_adc): one feedback potentiometer per joint, joint 1 first, then the battery's
// divider. hal/avr/pins.h maps them to the Nano's pins.
constexpr uint8_t kAdcInputs = kJoints + 1;
constexpr uint8_t kBatteryInput = kJoints;
constexpr float kAdcReferenceV = 5.0f;  // AVCC: the Nano's 5 V

}  // namespace cfg
