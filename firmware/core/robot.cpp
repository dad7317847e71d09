#include "robot.h"

#include <stddef.h>
#include <string.h>

#include "message_codec.h"
#include "pd.h"
#include "settings_codec.h"
#include "time_util.h"

namespace {
using eelproto::MsgId;
using eelproto::RefuseReason;

// Keep the cadence (next = previous + period) unless we fell a whole period behind, then restart
// it from now rather than firing a burst of late updates.
uint32_t next_deadline(uint32_t previous_us, uint32_t period_us, uint32_t now_us) {
  const uint32_t next = previous_us + period_us;
  return deadline_reached(now_us, next) ? now_us + period_us : next;
}

constexpr uint8_t reason(RefuseReason r) { return static_cast<uint8_t>(r); }
constexpr uint8_t bit(eelproto::Flags f) { return static_cast<uint8_t>(f); }
// The Status frames come half a telemetry period after the Telemetry frames: the two together
// would not leave the replies their room in the transmit queue (CommandLink::kReplyRoomBytes), so
// one would wait for the other to go out.
constexpr uint32_t kStatusPhaseUs = cfg::kTelemetryPeriodUs / 2;
static_assert(CommandLink::frame_bytes(eelproto::Telemetry::kPayloadBytes) +
                      CommandLink::kReplyRoomBytes <=
                  CommandLink::TxQueue::kCapacity &&
              CommandLink::frame_bytes(eelproto::Status::kPayloadBytes) +
                      CommandLink::kReplyRoomBytes <=
                  CommandLink::TxQueue::kCapacity,
              "an empty transmit queue must take each periodic frame and still leave the replies "
              "their room");
constexpr int16_t kNotMeasuredMrad = -32768;

// Milliradians, rounded. Within +-32.767 rad: the feedback's range (1023 counts at no less than
// 10 counts/rad) is smaller.
int16_t to_mrad(float rad) {
  const float mrad = rad * 1000.0f;
  return static_cast<int16_t>(mrad < 0.0f ? mrad - 0.5f : mrad + 0.5f);
}
}  // namespace

void Robot::reset(uint32_t now_us, const BootInfo& boot, const uint8_t* eeprom) {
  state_ = State::Idle;
  boot_ = boot;
  control_period_us_ = cfg::kControlPeriodUs;
  const StoredSettings stored = settings_from_eeprom(eeprom, settings_);
  settings_source_ = stored.source;
  stored_slot_ = stored.slot;
  stored_generation_ = stored.generation;
  stored_valid_ = stored.source == eelproto::SettingsSource::Eeprom;
  settings_lost_ = stored.source != eelproto::SettingsSource::Eeprom;
  writer_ = SettingsWriter{};
  settings_dirty_ = false;
  joints_.configure(settings_);
  const eelproto::SetGait g = eelproto::defaults<eelproto::SetGait>();
  gait_cmd_ = GaitTargets{g.amplitude_rad, g.omega_rad_s, g.beta_rad, 0.0f};
  apply_targets(now_us);
  gait_.reset(now_us);
  joints_.reset();
  battery_.reset();
  link_.reset(now_us);
  next_control_us_ = now_us;
  last_control_us_ = now_us;
  next_telemetry_us_ = now_us;
  next_status_us_ = now_us + kStatusPhaseUs;
  control_updates_ = 0;
  control_late_max_us_ = 0;
  telemetry_due_ = false;
  status_due_ = false;
  status_requested_ = false;
  control_update(now_us);
  joint_update(nullptr);
}

// Targets follow the state: undulate with the commanded gait only while running; otherwise go
// straight (amplitude and offset to 0) at no less than the straightening rate.
void Robot::apply_targets(uint32_t now_us) {
  GaitTargets t = gait_cmd_;
  GaitRates r{settings_.amplitude_rate_rad_s, settings_.beta_rate_rad_s,
              settings_.offset_rate_rad_s};
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
  gait_.set_targets(t, now_us);
  gait_.set_rates(r);
}

void Robot::enter(State s, uint32_t now_us) {
  if (s == state_) return;
  state_ = s;
  apply_targets(now_us);
  telemetry_due_ = true;  // say so at once, not up to 100 ms later
}

void Robot::on_rx_byte(uint8_t byte, uint32_t now_us) {
  const Frame* f = link_.push(byte, now_us);
  if (f != nullptr) handle(*f, now_us);
}

template <typename M>
bool Robot::accept(const Frame& f, M& m) {
  eelproto::unpack(m, f.payload);
  const uint8_t why = eelproto::validate(m);
  if (why) link_.refuse(f.msg_id, f.seq, why);
  return why == 0;
}

// Settings are changed, reset and saved only while the robot does not undulate: a new trim or
// calibration mid-stroke would jerk the joints.
bool Robot::settings_locked(const Frame& f) {
  if (state_ != State::Running) return false;
  link_.refuse(f.msg_id, f.seq, reason(RefuseReason::NotWhileRunning));
  return true;
}

// SetGait's rates and SetGains's gains are settings: the commands' fields were checked against
// the same ranges (protocol/eelbot.toml, "from"), so they are stored as they are.
__attribute__((noinline)) void Robot::store_setting(float& field, float value) {
  settings_dirty_ = settings_dirty_ || field != value;
  field = value;
}

void Robot::set_rate_settings(const eelproto::SetGait& m) {
  store_setting(settings_.amplitude_rate_rad_s, m.amplitude_rate_rad_s);
  store_setting(settings_.beta_rate_rad_s, m.beta_rate_rad_s);
  store_setting(settings_.offset_rate_rad_s, m.offset_rate_rad_s);
}

void Robot::set_gain_settings(const eelproto::SetGains& m) {
  store_setting(settings_.kp_nm_per_rad, m.kp_nm_per_rad);
  store_setting(settings_.kd_nms_per_rad, m.kd_nms_per_rad);
  store_setting(settings_.torque_limit_nm, m.torque_limit_nm);
}

void Robot::handle(const Frame& f, uint32_t now_us) {
  switch (static_cast<MsgId>(f.msg_id)) {
    case MsgId::Hello:
      send_version();
      return;
    case MsgId::GetStatus:
      status_requested_ = true;  // answered by the next service(), after the control update
      return;
    case MsgId::GetSetting: {
      eelproto::GetSetting m;
      eelproto::unpack(m, f.payload);
      float value = 0.0f;
      const uint8_t why = eelproto::setting_get(settings_, m.key, m.index, value);
      if (why) {
        link_.refuse(f.msg_id, f.seq, why);
      } else {
        link_.reply(eelproto::Setting{m.key, m.index, value});
      }
      return;
    }
    case MsgId::SetGait: {
      eelproto::SetGait m;
      if (!accept(f, m)) return;
      gait_cmd_.amplitude_rad = m.amplitude_rad;
      gait_cmd_.omega_rad_s = m.omega_rad_s;
      gait_cmd_.beta_rad = m.beta_rad;
      set_rate_settings(m);
      break;
    }
    case MsgId::SetOffset: {
      eelproto::SetOffset m;
      if (!accept(f, m)) return;
      gait_cmd_.offset_rad = m.offset_rad;
      break;
    }
    case MsgId::SetGains: {
      eelproto::SetGains m;
      if (!accept(f, m)) return;
      set_gain_settings(m);
      break;
    }
    case MsgId::Start:
      if (state_ == State::LowBattery) {
        link_.refuse(f.msg_id, f.seq, reason(RefuseReason::LowBattery));
        return;
      }
      // Lost settings (trims, calibration, the battery divider) are not guessed at: the host
      // says that the defaults will do first (docs/firmware.md, "Settings in the EEPROM").
      if (settings_lost_) {
        link_.refuse(f.msg_id, f.seq, reason(RefuseReason::SettingsLost));
        return;
      }
      // From straight, restart the phase so that t = 0 is now, as in the twin. From a
      // half-finished stop the phase runs on, so nothing jumps.
      if (state_ != State::Running) gait_.restart_phase(now_us);
      state_ = State::Running;
      break;
    case MsgId::Stop:
      if (state_ != State::LowBattery) state_ = State::Idle;
      break;
    case MsgId::SetSetting: {
      if (settings_locked(f)) return;
      eelproto::SetSetting m;
      eelproto::unpack(m, f.payload);
      bool changed = false;
      const uint8_t why = eelproto::setting_set(settings_, m.key, m.index, m.value, changed);
      if (why) {
        link_.refuse(f.msg_id, f.seq, why);
        return;
      }
      settings_dirty_ = settings_dirty_ || changed;
      joints_.configure(settings_);
      break;
    }
    case MsgId::DefaultSettings:
      if (settings_locked(f)) return;
      settings_ = eelproto::settings_defaults();
      settings_dirty_ = true;
      settings_lost_ = false;  // the host knows the defaults are in use
      joints_.configure(settings_);
      break;
    case MsgId::SaveSettings: {
      if (settings_locked(f)) return;
      // Into the slot that does not boot now, one generation on; the board writes it byte by
      // byte (app_tick) and save_done() answers.
      save_slot_ = stored_valid_ ? static_cast<uint8_t>(1 - stored_slot_) : 0;
      writer_.start(settings_, static_cast<uint16_t>(stored_generation_ + 1),
                    settings_slot_address(save_slot_));
      settings_dirty_ = false;  // set again by a change during the write, or by a failure
      save_msg_seq_ = f.seq;
      return;
    }
    default:
      return;  // unreachable: the link passes only messages to the robot, all handled above
  }
  apply_targets(now_us);
  link_.ack(f.msg_id, f.seq);
}

void Robot::save_done(bool ok) {
  const uint8_t id = static_cast<uint8_t>(MsgId::SaveSettings);
  if (ok) {
    stored_slot_ = save_slot_;
    ++stored_generation_;
    stored_valid_ = true;
    settings_lost_ = false;  // what the host chose is stored: nothing is lost any more
    link_.ack(id, save_msg_seq_);
  } else {
    settings_dirty_ = true;
    link_.refuse(id, save_msg_seq_, reason(RefuseReason::StorageFailed));
  }
}

bool Robot::control_due(uint32_t now_us) const {
  return control_period_us_ == 0 || deadline_reached(now_us, next_control_us_);
}

bool Robot::wants_adc() const {
  return settings_.joint_feedback != 0 || settings_.battery_divider > 0.0f;
}

void Robot::control_update(uint32_t now_us) {
  if (control_period_us_ != 0) {
    const uint32_t late_us = elapsed_us(now_us, next_control_us_);
    if (late_us > control_late_max_us_) {
      control_late_max_us_ = late_us > 0xFFFFu ? 0xFFFFu : static_cast<uint16_t>(late_us);
    }
  }
  next_control_us_ = next_deadline(next_control_us_, control_period_us_, now_us);
  control_dt_us_ = elapsed_us(now_us, last_control_us_);
  last_control_us_ = now_us;
  ++control_updates_;
  if (state_ == State::Running && link_.watchdog().expired(now_us)) enter(State::Failsafe, now_us);
  fading_ = gait_.update(now_us, link_.watchdog().envelope_rad(now_us));
}

void Robot::joint_update(const uint16_t* adc_counts) {
  battery_sampled_ = adc_counts != nullptr;
  if (battery_sampled_) battery_counts_ = adc_counts[cfg::kBatteryInput];
  const bool feedback = battery_sampled_ && settings_.joint_feedback != 0;
  joints_.update(settings_, gait_.alpha_rad(), gait_.alpha_dot_rad_s(),
                 feedback ? adc_counts : nullptr, control_dt_us_);
}

// The battery is health, not control: its filter runs after the update (outside its timing), and
// a low battery changes the targets from the next update on.
void Robot::update_battery(uint32_t now_us) {
  if (battery_sampled_) {
    battery_.update(settings_, battery_counts_, control_dt_us_);
  } else {
    battery_.reset();
  }
  if (battery_.low()) {
    enter(State::LowBattery, now_us);
  } else if (state_ == State::LowBattery) {
    enter(State::Idle, now_us);
  }
}

// Replies first (docs/firmware.md, "Link"): a due Telemetry or periodic Status is queued only
// when it leaves the replies their room; otherwise it waits for the next control update, keeping
// its cadence (a frame that waited is sent once, with the newer figures). The Status a GetStatus
// asked for is a reply.
void Robot::service(uint32_t now_us) {
  update_battery(now_us);
  if (deadline_reached(now_us, next_telemetry_us_)) {
    next_telemetry_us_ = next_deadline(next_telemetry_us_, cfg::kTelemetryPeriodUs, now_us);
    telemetry_due_ = true;
  }
  if (telemetry_due_ && link_.periodic_fits(eelproto::Telemetry::kPayloadBytes)) {
    telemetry_due_ = false;
    send_telemetry(now_us);
  }
  if (deadline_reached(now_us, next_status_us_)) {
    next_status_us_ = next_deadline(next_status_us_, cfg::kStatusPeriodUs, now_us);
    status_due_ = true;
  }
  if (status_requested_ ||
      (status_due_ && link_.periodic_fits(eelproto::Status::kPayloadBytes))) {
    send_status(now_us, status_requested_);
    status_requested_ = false;
    status_due_ = false;
  }
}

void Robot::joint_torques(const float* phi_rad, const float* phi_dot_rad_s,
                          float* torque_nm) const {
  const PdGains g{settings_.kp_nm_per_rad, settings_.kd_nms_per_rad, settings_.torque_limit_nm};
  pd_torques_nm(g, gait_.alpha_rad(), gait_.alpha_dot_rad_s(), phi_rad, phi_dot_rad_s, torque_nm,
                cfg::kJoints);
}

uint8_t Robot::flags() const {
  uint8_t f = 0;
  if (fading_) f |= bit(eelproto::Flags::Fading);
  if (joints_.measured()) f |= bit(eelproto::Flags::JointFeedback);
  if (settings_.battery_divider > 0.0f) f |= bit(eelproto::Flags::BatterySense);
  if (boot_.hw_watchdog) f |= bit(eelproto::Flags::HwWatchdog);
  if (settings_dirty_) f |= bit(eelproto::Flags::SettingsUnsaved);
  if (settings_lost_) f |= bit(eelproto::Flags::SettingsLost);
  return f;
}

void Robot::send_version() {
  link_.reply(eelproto::Version{cfg::kFirmwareMajor, cfg::kFirmwareMinor,
                                eelproto::kProtocolVersion, cfg::kJoints, eelproto::kSchemaHash,
                                cfg::kControlPeriodUs, eelproto::kSettingsVersion,
                                settings_.radio_id});
}

void Robot::send_telemetry(uint32_t now_us) {
  eelproto::Telemetry m;
  m.time_us = now_us;
  m.state = static_cast<uint8_t>(state_);
  m.flags = flags();
  const LinkCounters& c = link_.counters();
  for (uint8_t j = 0; j < cfg::kJoints; ++j) {
    m.alpha_rad[j] = gait_.alpha_rad()[j];
    m.phi_mrad[j] = joints_.measured() ? to_mrad(joints_.phi_rad()[j]) : kNotMeasuredMrad;
  }
  m.offset_rad = gait_.offset_rad();
  m.amplitude_rad = gait_.amplitude_rad();
  m.frames_ok = c.frames_ok;
  m.frames_bad = c.bad_total();
  m.frames_lost = c.lost;
  link_.send_periodic(m);
}

void Robot::send_status(uint32_t now_us, bool asked) {
  eelproto::Status m;
  m.time_us = now_us;
  m.state = static_cast<uint8_t>(state_);
  m.flags = flags();
  m.reset_flags = boot_.reset_flags;
  m.resets = boot_.resets;
  m.settings_source = static_cast<uint8_t>(settings_source_);
  m.battery_v = battery_.volts();
  m.control_late_max_us = control_late_max_us_;
  // The counters close the message in LinkCounters' order: one copy rather than 13 (flash).
  static_assert(offsetof(LinkCounters, frames_ok) == 0 &&
                    offsetof(eelproto::Status, tx_dropped) - offsetof(eelproto::Status, frames_ok) ==
                        offsetof(LinkCounters, tx_dropped) &&
                    sizeof(LinkCounters) == offsetof(LinkCounters, tx_dropped) + sizeof(uint16_t),
                "Status's counters must be LinkCounters' fields in order");
  memcpy(&m.frames_ok, &link_.counters(), sizeof(LinkCounters));
  if (asked) {
    link_.reply(m);
  } else {
    link_.send_periodic(m);
  }
}
