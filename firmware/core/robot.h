// The robot's program without its board: commands in (bytes), state machine, gait, failsafe,
// joint loop, settings, health, servo pulses out, telemetry and replies out (bytes). Time is
// always an argument. The board layer (hal/avr or hal/native) moves the bytes, pulses, analog
// readings and EEPROM bytes; app/app.h wires the two.
#pragma once
#include <stdint.h>

#include "battery.h"
#include "boot.h"
#include "command_link.h"
#include "config.h"
#include "gait.h"
#include "joint_loop.h"
#include "protocol_gen.h"
#include "settings_store.h"
#include "settings_writer.h"

class Robot {
 public:
  using State = eelproto::State;
  using TxQueue = CommandLink::TxQueue;

  // Boot state: IDLE, straight, settings from the newer valid EEPROM slot (`eeprom`: the
  // kSettingsEepromBytes from kSettingsEepromAddress), or the defaults with the flag SETTINGS_LOST
  // when neither slot is valid (blank, corrupt or of another settings version), counters zero.
  void reset(uint32_t now_us, const BootInfo& boot, const uint8_t* eeprom);
  // One received byte; a completed command is executed at once (it only sets parameters: the
  // gait is computed in control_update, once per control period, however many commands come).
  void on_rx_byte(uint8_t byte, uint32_t now_us);
  bool control_due(uint32_t now_us) const;
  // The board samples the analog inputs (cfg::kAdcInputs) for joint_update when this is true.
  bool wants_adc() const;
  // Control update at now_us: failsafe, link-loss envelope, the gait.
  void control_update(uint32_t now_us);
  // Then the rest of it with this update's analog readings (nullptr when wants_adc() was false):
  // measured angles, joint loop, servo pulses.
  void joint_update(const uint16_t* adc_counts);
  // After the update: the battery's reading of it, Telemetry and Status frames when due (each
  // only with room left for the replies, else at a later update: docs/firmware.md, "Link").
  void service(uint32_t now_us);

  // SaveSettings: the board steps this writer once a loop pass (a byte at a time, while control
  // runs) and calls save_done with whether the slot read back; the robot then answers the command.
  SettingsWriter& settings_writer() { return writer_; }
  void save_done(bool ok);
  // The slot that boots next (the newer valid one), and whether the settings were lost at boot
  // and not yet acknowledged (Start refused).
  uint8_t stored_slot() const { return stored_slot_; }
  bool settings_lost() const { return settings_lost_; }

  // Joint PD torques for plant joint angles and rates (the native build's simulated plant).
  void joint_torques(const float* phi_rad, const float* phi_dot_rad_s, float* torque_nm) const;
  // 0 runs the control update on every call of control_due (the native build's lockstep option).
  void set_control_period_us(uint32_t period_us) { control_period_us_ = period_us; }

  State state() const { return state_; }
  uint8_t flags() const;
  const Gait& gait() const { return gait_; }
  const eelproto::Settings& settings() const { return settings_; }
  eelproto::SettingsSource settings_source() const { return settings_source_; }
  const JointLoop& joints() const { return joints_; }
  const BatteryMonitor& battery() const { return battery_; }
  const uint16_t* pulse_us() const { return joints_.pulse_us(); }
  const LinkCounters& counters() const { return link_.counters(); }
  const LinkWatchdog& watchdog() const { return link_.watchdog(); }
  const BootInfo& boot() const { return boot_; }
  uint16_t control_updates() const { return control_updates_; }
  uint16_t control_late_max_us() const { return control_late_max_us_; }
  TxQueue& tx() { return link_.tx(); }

 private:
  void handle(const Frame& f, uint32_t now_us);
  template <typename M>
  bool accept(const Frame& f, M& m);
  void apply_targets(uint32_t now_us);
  void enter(State s, uint32_t now_us);
  void update_battery(uint32_t now_us);
  bool settings_locked(const Frame& f);
  void set_rate_settings(const eelproto::SetGait& m);
  void set_gain_settings(const eelproto::SetGains& m);
  void store_setting(float& field, float value);
  void send_version();
  void send_telemetry(uint32_t now_us);
  void send_status(uint32_t now_us, bool asked);

  State state_ = State::Idle;
  Gait gait_;
  GaitTargets gait_cmd_{};      // what the host asked for (applies while running)
  eelproto::Settings settings_{};
  eelproto::SettingsSource settings_source_ = eelproto::SettingsSource::Eeprom;
  JointLoop joints_;
  BatteryMonitor battery_;
  CommandLink link_;
  BootInfo boot_{};
  uint32_t control_period_us_ = 0;  // set by reset(): a zero initialiser keeps the object in .bss
  uint32_t next_control_us_ = 0;
  uint32_t last_control_us_ = 0;
  uint32_t control_dt_us_ = 0;     // since the update before
  uint16_t battery_counts_ = 0;    // the battery's reading at the last update
  uint32_t next_telemetry_us_ = 0;
  uint32_t next_status_us_ = 0;
  uint16_t control_updates_ = 0;
  uint16_t control_late_max_us_ = 0;
  SettingsWriter writer_;
  uint16_t stored_generation_ = 0; // of the slot that boots next
  uint8_t stored_slot_ = 0;
  uint8_t save_slot_ = 0;          // the slot being written
  bool stored_valid_ = false;      // a valid slot exists (else a save writes slot 0)
  uint8_t save_msg_seq_ = 0;       // the SaveSettings being written
  bool settings_lost_ = false;     // no valid slot at boot, not yet acknowledged: Start refused
  bool settings_dirty_ = false;
  bool fading_ = false;
  bool telemetry_due_ = false;     // due (its time, or a state change), waiting for room
  bool status_due_ = false;        // the periodic Status due, waiting for room
  bool status_requested_ = false;  // a GetStatus: answered (a reply) at the next service
  bool battery_sampled_ = false;   // battery_counts_ is of the last update
};
