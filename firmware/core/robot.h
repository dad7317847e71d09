// The robot's program without its board: commands in (bytes), state machine, gait, failsafe,
// references and servo pulses out, telemetry and replies out (bytes). Time is always an argument.
// The board layer (hal/avr or hal/native) moves the bytes and pulses; app/app.h wires the two.
#pragma once
#include <stdint.h>

#include "byte_queue.h"
#include "config.h"
#include "frame_codec.h"
#include "gait.h"
#include "link_counters.h"
#include "link_watchdog.h"
#include "pd.h"
#include "protocol_gen.h"

class Robot {
 public:
  using State = eelproto::State;
  // Room for a telemetry frame and a couple of replies between two drains of the UART.
  using TxQueue = ByteQueue<128>;

  // Boot state: IDLE, straight, default gait/gains from protocol/eelbot.toml, counters zero.
  void reset(uint32_t now_us);
  void on_rx_byte(uint8_t byte, uint32_t now_us);
  // Failsafe check and telemetry; call every loop.
  void service(uint32_t now_us);
  bool control_due(uint32_t now_us) const;
  // Gait update at now_us: references, clamps, servo pulses.
  void control_update(uint32_t now_us);
  // Joint PD torques for measured joint angles and rates (the native build's plant).
  void joint_torques(const float* phi_rad, const float* phi_dot_rad_s, float* torque_nm) const;

  // 0 runs the control update on every call of control_due (the native build's lockstep option).
  void set_control_period_us(uint32_t period_us) { control_period_us_ = period_us; }

  State state() const { return state_; }
  const Gait& gait() const { return gait_; }
  const PdGains& gains() const { return gains_; }
  const uint16_t* pulse_us() const { return pulse_us_; }
  const LinkCounters& counters() const { return counters_; }
  const LinkWatchdog& watchdog() const { return watchdog_; }
  TxQueue& tx() { return tx_; }

 private:
  void handle(const Frame& f, uint32_t now_us);
  bool accept_seq(uint8_t msg_id, uint8_t seq);
  // Decode a command's payload into m; refuse it (and return false) when a field is not valid.
  template <typename M>
  bool accept(const Frame& f, M& m);
  void apply_targets();
  template <typename M>
  void send(const M& m);
  void send(uint8_t msg_id, const uint8_t* payload, uint8_t len);
  void ack(const Frame& f);
  void refuse(const Frame& f, uint8_t reason);
  void send_version();
  void send_telemetry(uint32_t now_us);

  State state_ = State::Idle;
  Gait gait_;
  eelproto::SetGait gait_cmd_{};  // what the host asked for (targets apply while running)
  float offset_cmd_rad_ = 0.0f;
  PdGains gains_{};
  uint16_t pulse_us_[cfg::kJoints] = {};
  FrameDecoder decoder_;
  LinkCounters counters_{};
  LinkWatchdog watchdog_;
  TxQueue tx_;
  uint32_t control_period_us_ = 0;  // set by reset(): a zero initialiser keeps the object in .bss
  uint32_t next_control_us_ = 0;
  uint32_t next_telemetry_us_ = 0;
  uint8_t tx_seq_ = 0;
  uint8_t last_rx_seq_ = 0;
  bool have_rx_seq_ = false;
};
