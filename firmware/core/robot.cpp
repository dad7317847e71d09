#include "robot.h"

#include "message_codec.h"
#include "servo_map.h"
#include "time_util.h"

namespace {
// Keep the cadence (next = previous + period) unless we fell a whole period behind, then restart
// it from now rather than firing a burst of late updates.
uint32_t next_deadline(uint32_t previous_us, uint32_t period_us, uint32_t now_us) {
  const uint32_t next = previous_us + period_us;
  return deadline_reached(now_us, next) ? now_us + period_us : next;
}
}  // namespace

void Robot::reset(uint32_t now_us) {
  state_ = State::Idle;
  control_period_us_ = cfg::kControlPeriodUs;
  gait_cmd_ = eelproto::defaults<eelproto::SetGait>();
  offset_cmd_rad_ = 0.0f;
  const eelproto::SetGains g = eelproto::defaults<eelproto::SetGains>();
  gains_ = PdGains{g.kp_nm_per_rad, g.kd_nms_per_rad, g.torque_limit_nm};
  apply_targets();
  gait_.reset(now_us);
  decoder_.clear();
  counters_ = LinkCounters{};
  watchdog_.feed(now_us);
  tx_.clear();
  next_control_us_ = now_us;
  next_telemetry_us_ = now_us;
  tx_seq_ = 0;
  have_rx_seq_ = false;
  control_update(now_us);
}

// Targets follow the state: undulate with the commanded gait only while running; otherwise go
// straight (amplitude and offset to 0) at no less than the straightening rate.
void Robot::apply_targets() {
  GaitTargets t{gait_cmd_.amplitude_rad, gait_cmd_.omega_rad_s, gait_cmd_.beta_rad, offset_cmd_rad_};
  GaitRates r{gait_cmd_.amplitude_rate_rad_s, gait_cmd_.beta_rate_rad_s,
              gait_cmd_.offset_rate_rad_s};
  if (state_ != State::Running) {
    t.amplitude_rad = 0.0f;
    t.offset_rad = 0.0f;
    if (r.amplitude_rad_s > 0.0f && r.amplitude_rad_s < cfg::kStraightenMinRateRadS) {
      r.amplitude_rad_s = cfg::kStraightenMinRateRadS;
    }
    if (r.offset_rad_s > 0.0f && r.offset_rad_s < cfg::kStraightenMinRateRadS) {
      r.offset_rad_s = cfg::kStraightenMinRateRadS;
    }
  }
  gait_.set_targets(t);
  gait_.set_rates(r);
}

void Robot::on_rx_byte(uint8_t byte, uint32_t now_us) {
  if (decoder_.push(byte, counters_)) handle(decoder_.frame(), now_us);
}

// Sequence numbers: a gap counts as lost frames; a repeat of the previous number is a duplicate
// (a radio retry) and is ignored; a jump backwards by more than half the range is taken as a host
// restart and resynchronises without counting. Hello always resynchronises.
bool Robot::accept_seq(uint8_t msg_id, uint8_t seq) {
  const bool resync = !have_rx_seq_ || msg_id == static_cast<uint8_t>(eelproto::MsgId::Hello);
  const uint8_t gap = static_cast<uint8_t>(seq - static_cast<uint8_t>(last_rx_seq_ + 1));
  if (!resync) {
    if (gap == 0xFF) {
      ++counters_.duplicates;
      return false;
    }
    if (gap < 0x80) counters_.lost = static_cast<uint16_t>(counters_.lost + gap);
  }
  have_rx_seq_ = true;
  last_rx_seq_ = seq;
  return true;
}

void Robot::handle(const Frame& f, uint32_t now_us) {
  using eelproto::MsgId;
  if (!accept_seq(f.msg_id, f.seq)) return;
  ++counters_.frames_ok;
  watchdog_.feed(now_us);  // any valid frame proves the link
  if (!eelproto::is_to_robot(f.msg_id)) {
    refuse(f, static_cast<uint8_t>(eelproto::RefuseReason::Unsupported));
    return;
  }
  gait_.update(now_us);  // the old parameters hold up to now, the new ones from now on
  switch (static_cast<MsgId>(f.msg_id)) {
    case MsgId::Hello:
      send_version();
      return;
    case MsgId::SetGait: {
      eelproto::SetGait m;
      if (!accept(f, m)) return;
      gait_cmd_ = m;
      break;
    }
    case MsgId::SetOffset: {
      eelproto::SetOffset m;
      if (!accept(f, m)) return;
      offset_cmd_rad_ = m.offset_rad;
      break;
    }
    case MsgId::SetGains: {
      eelproto::SetGains m;
      if (!accept(f, m)) return;
      gains_ = PdGains{m.kp_nm_per_rad, m.kd_nms_per_rad, m.torque_limit_nm};
      break;
    }
    case MsgId::Start:
      // From straight, restart the phase so that t = 0 is now, as in the twin. From a
      // half-finished stop the phase runs on, so nothing jumps.
      if (state_ != State::Running) gait_.restart_phase(now_us);
      state_ = State::Running;
      break;
    case MsgId::Stop:
      state_ = State::Idle;
      break;
    default:
      return;  // unreachable: is_to_robot() admits only the cases above
  }
  apply_targets();
  ack(f);
}

template <typename M>
bool Robot::accept(const Frame& f, M& m) {
  eelproto::unpack(m, f.payload);
  const uint8_t why = eelproto::validate(m);
  if (why) refuse(f, why);
  return why == 0;
}

void Robot::service(uint32_t now_us) {
  if (state_ == State::Running && watchdog_.expired(now_us)) {
    gait_.update(now_us);
    state_ = State::Failsafe;
    apply_targets();
    send_telemetry(now_us);  // say so at once, not up to 100 ms later
  }
  if (deadline_reached(now_us, next_telemetry_us_)) {
    next_telemetry_us_ = next_deadline(next_telemetry_us_, cfg::kTelemetryPeriodUs, now_us);
    send_telemetry(now_us);
  }
}

bool Robot::control_due(uint32_t now_us) const {
  return control_period_us_ == 0 || deadline_reached(now_us, next_control_us_);
}

void Robot::control_update(uint32_t now_us) {
  next_control_us_ = next_deadline(next_control_us_, control_period_us_, now_us);
  gait_.update(now_us);
  const float* alpha = gait_.alpha_rad();
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    pulse_us_[j] = servo_pulse_us(kServoCalibration[j], alpha[j]);
  }
}

void Robot::joint_torques(const float* phi_rad, const float* phi_dot_rad_s,
                          float* torque_nm) const {
  pd_torques_nm(gains_, gait_.alpha_rad(), gait_.alpha_dot_rad_s(), phi_rad, phi_dot_rad_s,
                torque_nm, cfg::kJoints);
}

void Robot::send(uint8_t msg_id, const uint8_t* payload, uint8_t len) {
  uint8_t buf[eelproto::kMaxFrameBytes];
  const size_t n = encode_frame(msg_id, tx_seq_, payload, len, buf, sizeof(buf));
  if (n == 0 || !tx_.push_all(buf, n)) {
    ++counters_.tx_dropped;
    return;
  }
  ++tx_seq_;
}

template <typename M>
void Robot::send(const M& m) {
  uint8_t p[M::kPayloadBytes];
  eelproto::pack(m, p);
  send(static_cast<uint8_t>(M::kId), p, sizeof(p));
}

void Robot::ack(const Frame& f) { send(eelproto::Ack{f.msg_id, f.seq}); }

void Robot::refuse(const Frame& f, uint8_t reason) {
  send(eelproto::Refuse{f.msg_id, f.seq, reason});
}

void Robot::send_version() {
  send(eelproto::Version{cfg::kFirmwareMajor, cfg::kFirmwareMinor, eelproto::kProtocolVersion,
                         cfg::kJoints, eelproto::kSchemaHash, cfg::kControlPeriodUs});
}

void Robot::send_telemetry(uint32_t now_us) {
  eelproto::Telemetry m;
  m.time_us = now_us;
  m.state = static_cast<uint8_t>(state_);
  for (uint8_t j = 0; j < cfg::kJoints; ++j) m.alpha_rad[j] = gait_.alpha_rad()[j];
  m.offset_rad = gait_.offset_rad();
  m.amplitude_rad = gait_.amplitude_rad();
  m.frames_ok = counters_.frames_ok;
  m.frames_bad = counters_.bad_total();
  m.frames_lost = counters_.lost;
  send(m);
}
