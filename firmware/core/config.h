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
constexpr uint8_t kFirmwareMinor = 1;

// Mechanical range of every joint module; references (and so servo pulses) are clamped to it.
constexpr float kJointLimitRad = 1.2f;

constexpr uint32_t kControlPeriodUs = eelproto::kControlPeriodUs;
constexpr uint32_t kTelemetryPeriodUs = eelproto::kTelemetryPeriodUs;
constexpr uint32_t kLinkTimeoutUs = eelproto::kLinkTimeoutUs;  // failsafe after this long quiet
// When straightening (Stop, failsafe) the amplitude and offset move at least this fast, so that a
// tiny configured slew rate cannot keep the robot undulating for long after the link is lost.
constexpr float kStraightenMinRateRadS = 1.0f;

}  // namespace cfg
