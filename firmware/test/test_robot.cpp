#include <math.h>
#include <string.h>

#include "check.h"
#include "frames.h"
#include "robot.h"
#include "settings_codec.h"

namespace {
using eelproto::MsgId;
using eelproto::SettingKey;
using eelproto::State;

constexpr uint8_t kPowerOn = static_cast<uint8_t>(eelproto::ResetFlags::PowerOn);
uint8_t why(eelproto::RefuseReason r) { return static_cast<uint8_t>(r); }
uint8_t bit(eelproto::Flags f) { return static_cast<uint8_t>(f); }

eelproto::SetOffset offset(float v) {
  eelproto::SetOffset m;
  m.offset_rad = v;
  return m;
}

// The robot with a clock, its analog inputs and EEPROM, and a decoder for what it sends back. The
// passes follow app/app.h: commands, then (when due) the control update, the joint update with
// the analog readings, telemetry and status.
struct Bench {
  Robot robot;
  uint32_t now = 0;
  uint8_t seq = 0;
  uint16_t adc[cfg::kAdcInputs];
  uint8_t eeprom[kSettingsEepromBytes];
  bool eeprom_fails = false;
  int saves = 0;            // saves finished
  int eeprom_writes = 0;    // bytes programmed
  FrameDecoder out_decoder;
  LinkCounters out_counters{};
  int acks = 0, refusals = 0, telemetry = 0, versions = 0, statuses = 0, settings = 0;
  uint8_t last_refuse_reason = 0;
  eelproto::Telemetry last_telemetry{};
  eelproto::Status last_status{};
  eelproto::Version last_version{};
  eelproto::Setting last_setting{};

  explicit Bench(uint32_t t0 = 0) : now(t0) {
    for (uint16_t& a : adc) a = 512;  // the battery input too: 8.0 V behind the default divider
    // A robot that has been set up: the defaults saved in slot 0.
    memset(eeprom, 0xFF, sizeof eeprom);
    settings_to_image(eelproto::settings_defaults(), eeprom + settings_slot_address(0), 1);
    boot(kPowerOn);
  }
  void boot(uint8_t reset_flags) {
    robot.reset(now, BootInfo{reset_flags, 0, false}, eeprom);
    drain();
  }

  void feed(const Bytes& b) {
    for (size_t i = 0; i < b.n; ++i) robot.on_rx_byte(b.data[i], now);
    pass_end();
  }
  template <class M>
  void send(const M& m) { feed(frame_of(m, seq++)); }

  // Run for `us` with the host's keep-alive (SetOffset every 300 ms).
  void run_alive(uint32_t us) {
    for (uint32_t t = 0; t < us; t += 100000) {
      run(100000);
      if ((t / 100000) % 3 == 2) send(offset(gait_offset));
    }
  }
  float gait_offset = 0.0f;

  // Run the main loop for `us` microseconds in 1 ms passes.
  void run(uint32_t us) {
    for (uint32_t t = 0; t < us; t += 1000) {
      now += 1000;
      if (robot.control_due(now)) {
        robot.control_update(now);
        robot.joint_update(robot.wants_adc() ? adc : nullptr);
        robot.service(now);
      }
      pass_end();
    }
  }
  // The board's EEPROM for the SettingsWriter (instant here; app.h's pass writes one byte).
  bool eeprom_ready() const { return true; }
  uint8_t eeprom_read(uint16_t a) const { return eeprom[a]; }
  void eeprom_write(uint16_t a, uint8_t v) {
    ++eeprom_writes;
    last_write_address = a;
    if (!eeprom_fails) eeprom[a] = v;
  }
  uint16_t last_write_address = 0;
  // The end of a pass: a save in progress runs to its end (a byte a pass on the robot).
  void pass_end() {
    for (;;) {
      const SettingsWriter::Step st = robot.settings_writer().step(*this);
      if (st == SettingsWriter::Step::Idle) break;
      if (st == SettingsWriter::Step::Writing) continue;
      ++saves;
      robot.save_done(st == SettingsWriter::Step::Written);
    }
    drain();
  }
  bool uart_stalled = false;  // the UART takes nothing: what is queued stays queued
  void drain() {
    Robot::TxQueue& tx = robot.tx();
    while (!uart_stalled && !tx.empty()) {
      if (!out_decoder.push(tx.pop(), out_counters)) continue;
      const Frame& f = out_decoder.frame();
      switch (static_cast<MsgId>(f.msg_id)) {
        case MsgId::Ack: ++acks; break;
        case MsgId::Refuse: {
          ++refusals;
          eelproto::Refuse r;
          eelproto::unpack(r, f.payload);
          last_refuse_reason = r.reason;
          break;
        }
        case MsgId::Telemetry:
          ++telemetry;
          eelproto::unpack(last_telemetry, f.payload);
          break;
        case MsgId::Status:
          ++statuses;
          eelproto::unpack(last_status, f.payload);
          break;
        case MsgId::Version:
          ++versions;
          eelproto::unpack(last_version, f.payload);
          break;
        case MsgId::Setting:
          ++settings;
          eelproto::unpack(last_setting, f.payload);
          break;
        default: break;
      }
    }
  }
  float max_abs_alpha() const {
    float m = 0.0f;
    for (int j = 0; j < cfg::kJoints; ++j) m = fmaxf(m, fabsf(robot.gait().alpha_rad()[j]));
    return m;
  }
  void set(SettingKey key, uint8_t index, float value) {
    send(eelproto::SetSetting{static_cast<uint8_t>(key), index, value});
  }
};

eelproto::SetGait gait(float amplitude_rad) {
  eelproto::SetGait g = eelproto::defaults<eelproto::SetGait>();
  g.amplitude_rad = amplitude_rad;
  return g;
}
}  // namespace

TEST(robot_boots_idle_and_straight) {
  Bench b;
  b.run(200000);
  CHECK(b.robot.state() == State::Idle);
  CHECK_EQ(b.max_abs_alpha(), 0.0f);
  for (int j = 0; j < cfg::kJoints; ++j) CHECK_EQ(b.robot.pulse_us()[j], 1500);
}

TEST(start_is_acknowledged_and_the_amplitude_ramps_up_at_its_rate) {
  Bench b;
  b.send(eelproto::Start{});
  CHECK_EQ(b.acks, 1);
  CHECK(b.robot.state() == State::Running);
  b.run(400000);
  CHECK_NEAR(b.robot.gait().amplitude_rad(), 0.5 * 0.4, 1e-4);  // default rate 0.5 rad/s
  b.send(offset(0.0f));  // keep the link alive
  b.run(700000);
  CHECK_NEAR(b.robot.gait().amplitude_rad(), 0.5, 1e-6);
}

TEST(hello_is_answered_with_the_version_and_the_radio_id) {
  Bench b;
  b.set(SettingKey::RadioId, 0, 4242.0f);
  b.send(eelproto::Hello{});
  CHECK_EQ(b.versions, 1);
  CHECK_EQ(b.last_version.radio_id, 4242);
  CHECK_EQ(b.last_version.settings_version, eelproto::kSettingsVersion);
  CHECK_EQ(b.last_version.schema_hash, eelproto::kSchemaHash);
}

TEST(out_of_range_gait_is_refused_and_changes_nothing) {
  Bench b;
  eelproto::SetGait g = gait(2.0f);
  g.omega_rad_s = 1.0f;
  b.send(g);
  CHECK_EQ(b.refusals, 1);
  CHECK_EQ(b.last_refuse_reason, why(eelproto::RefuseReason::OutOfRange));
  CHECK_EQ(b.robot.gait().targets().omega_rad_s, eelproto::defaults<eelproto::SetGait>().omega_rad_s);
}

TEST(nan_offset_is_refused_as_not_finite) {
  Bench b;
  b.send(offset(nanf("")));
  CHECK_EQ(b.refusals, 1);
  CHECK_EQ(b.last_refuse_reason, why(eelproto::RefuseReason::NotFinite));
}

TEST(an_echo_of_the_robots_own_frames_is_dropped_unanswered_and_keeps_no_link_alive) {
  // An XBee that echoes (or a loop-back on the bench) sends the robot its own telemetry and
  // acknowledgements: counted, never answered, and the failsafe still comes on time.
  Bench b;
  b.send(eelproto::Start{});
  const uint32_t last_command = b.now;
  for (int k = 0; k < 15; ++k) {
    b.run(100000);
    b.send(b.last_telemetry);
    b.send(eelproto::Ack{4, 0});
  }
  CHECK_EQ(b.robot.counters().bad_direction, 30);
  CHECK_EQ(b.acks, 1);
  CHECK_EQ(b.refusals, 0);
  CHECK(b.robot.state() == State::Failsafe);
  CHECK_EQ(b.robot.watchdog().last_valid_us(), last_command);
}

// Link loss with the default ramp rates (docs/firmware.md, "Failsafe"): straight 0.9 s after the
// last valid frame whatever the gait, FAILSAFE at 1 s.
void check_straight_by_0_9_s(float amplitude_rad, float offset_rad) {
  Bench b;
  b.send(gait(amplitude_rad));
  b.send(offset(offset_rad));
  b.send(eelproto::Start{});
  for (int k = 0; k < 12; ++k) {  // 3.6 s: at the default 0.5 rad/s even 1.5 rad is reached
    b.run(300000);
    b.send(offset(offset_rad));
  }
  CHECK_NEAR(b.robot.gait().amplitude_rad(), amplitude_rad, 1e-6);
  CHECK_NEAR(b.robot.gait().offset_rad(), offset_rad, 1e-6);
  const uint32_t last = b.now;
  float worst_after_rest = 0.0f;
  while (b.now - last < 1100000) {
    b.run(10000);
    const uint32_t quiet = b.now - last;
    if (quiet >= eelproto::kLinkRestUs) worst_after_rest = fmaxf(worst_after_rest, b.max_abs_alpha());
    if (quiet < eelproto::kLinkTimeoutUs) CHECK(b.robot.state() == State::Running);
    if (quiet >= eelproto::kLinkTimeoutUs) CHECK(b.robot.state() == State::Failsafe);
    if (quiet == 500000) CHECK(b.max_abs_alpha() > 0.1f);  // still undulating half-way
  }
  CHECK_EQ(worst_after_rest, 0.0f);
  for (int j = 0; j < cfg::kJoints; ++j) CHECK_EQ(b.robot.pulse_us()[j], 1500);
  CHECK_EQ(b.last_telemetry.state, static_cast<uint8_t>(State::Failsafe));
}

TEST(with_the_default_rates_the_default_gait_is_straight_0_9_s_after_the_last_frame) {
  check_straight_by_0_9_s(eelproto::defaults<eelproto::SetGait>().amplitude_rad, 0.0f);
}

TEST(with_the_default_rates_the_largest_gait_and_offset_are_straight_0_9_s_after_the_last_frame) {
  check_straight_by_0_9_s(1.5f, 1.0f);
  check_straight_by_0_9_s(1.5f, -1.0f);
}

TEST(the_fade_to_straight_has_no_jump) {
  Bench b;
  b.send(gait(1.5f));
  b.send(offset(0.8f));
  b.send(eelproto::Start{});
  for (int k = 0; k < 12; ++k) {
    b.run(300000);
    b.send(offset(0.8f));
  }
  float prev[cfg::kJoints];
  for (int j = 0; j < cfg::kJoints; ++j) prev[j] = b.robot.gait().alpha_rad()[j];
  float worst = 0.0f;
  bool faded = false;
  for (int k = 0; k < 150; ++k) {
    b.run(10000);
    faded = faded || (b.last_telemetry.flags & bit(eelproto::Flags::Fading)) != 0;
    for (int j = 0; j < cfg::kJoints; ++j) {
      worst = fmaxf(worst, fabsf(b.robot.gait().alpha_rad()[j] - prev[j]));
      prev[j] = b.robot.gait().alpha_rad()[j];
    }
  }
  // Per 10 ms: the undulation (A_1 omega dt = 1.5 * 5/7 * 3.14 * 0.01) plus the envelope on the
  // amplitude and on the offset (4 rad/s * 0.01 s each).
  const double bound = 1.5 * 5.0 / 7.0 * 3.1416 * 0.01 + 2 * 4.0 * 0.01;
  CHECK(worst <= bound);
  CHECK(faded);
  CHECK_EQ(b.max_abs_alpha(), 0.0f);
}

TEST(frames_every_300ms_keep_the_robot_running_without_fading) {
  Bench b;
  b.send(gait(1.5f));
  b.send(eelproto::Start{});
  for (int k = 0; k < 20; ++k) {
    b.run(300000);
    CHECK_EQ(b.last_telemetry.flags & bit(eelproto::Flags::Fading), 0);
    b.send(offset(0.1f));
  }
  CHECK(b.robot.state() == State::Running);
}

TEST(the_link_back_during_the_fade_lets_the_gait_grow_again_at_its_rate) {
  Bench b;
  b.send(eelproto::Start{});
  b.run_alive(1200000);
  b.send(offset(0.0f));
  b.run(850000);  // the default 0.5 rad now capped at 4 * 0.05 = 0.2 rad
  CHECK_NEAR(b.robot.gait().amplitude_rad(), 0.2, 1e-5);
  b.send(offset(0.0f));
  b.run(200000);
  CHECK_NEAR(b.robot.gait().amplitude_rad(), 0.2 + 0.5 * 0.2, 1e-5);
  CHECK(b.robot.state() == State::Running);
}

TEST(failsafe_fires_one_second_after_the_last_frame_across_the_micros_wrap) {
  Bench b(0xFFFFFFFFu - 400000u);
  b.send(eelproto::Start{});
  b.run(999000);  // crosses the wrap 0.4 s in
  CHECK(b.robot.state() == State::Running);
  b.run(10000);
  CHECK(b.robot.state() == State::Failsafe);
}

TEST(start_after_failsafe_resumes_undulating) {
  Bench b;
  b.send(eelproto::Start{});
  b.run(3000000);
  CHECK(b.robot.state() == State::Failsafe);
  b.send(eelproto::Start{});
  b.run(500000);
  CHECK(b.robot.state() == State::Running);
  CHECK(b.robot.gait().amplitude_rad() > 0.2f);
}

TEST(stop_returns_to_idle_and_straightens) {
  Bench b;
  b.send(offset(0.3f));
  b.send(eelproto::Start{});
  b.run(500000);
  b.send(eelproto::Stop{});
  b.run(400000);
  CHECK(b.robot.state() == State::Idle);
  CHECK_EQ(b.max_abs_alpha(), 0.0f);
}

TEST(telemetry_comes_every_100ms_and_status_every_second_half_a_period_later) {
  Bench b;
  b.run(2000000);
  CHECK(b.telemetry >= 20 && b.telemetry <= 21);
  CHECK_EQ(b.last_telemetry.time_us, 2000000u);
  CHECK_EQ(b.last_telemetry.frames_bad, 0);
  CHECK_EQ(b.statuses, 2);
  CHECK_EQ(b.last_status.time_us, 1050000u);
  b.send(eelproto::GetStatus{});
  b.run(10000);
  CHECK_EQ(b.statuses, 3);
  CHECK_EQ(b.last_status.time_us, 2010000u);
  CHECK_EQ(b.acks, 0);  // the Status is the answer
}

TEST(sequence_gaps_count_lost_frames) {
  Bench b;
  b.feed(frame_of(offset(0.1f), 10));
  b.feed(frame_of(offset(0.2f), 13));  // 11 and 12 lost
  CHECK_EQ(b.robot.counters().lost, 2);
  CHECK_EQ(b.acks, 2);
  b.feed(frame_of(offset(0.3f), 13));  // the same number, another command: a host restart
  CHECK_EQ(b.robot.counters().lost, 2);
  CHECK_EQ(b.robot.counters().duplicates, 0);
  CHECK_EQ(b.acks, 3);
}

TEST(a_repeated_command_is_answered_again_but_not_executed_again) {
  Bench b;
  const Bytes save = frame_of(eelproto::SaveSettings{}, 20);
  b.feed(save);
  b.feed(save);  // a radio retry
  CHECK_EQ(b.saves, 1);
  CHECK_EQ(b.acks, 2);
  const Bytes bad = frame_of(offset(5.0f), 21);
  b.feed(bad);
  b.feed(bad);
  CHECK_EQ(b.refusals, 2);
  CHECK_EQ(b.last_refuse_reason, why(eelproto::RefuseReason::OutOfRange));
  const Bytes query = frame_of(eelproto::GetSetting{1, 2}, 22);
  b.feed(query);
  b.feed(query);  // a query has no effect: answered again
  CHECK_EQ(b.settings, 2);
  CHECK_EQ(b.robot.counters().duplicates, 3);
  CHECK_EQ(b.robot.counters().frames_ok, 3);
}

TEST(every_kind_of_bad_frame_is_counted_and_never_acted_on) {
  Bench b;
  uint8_t p[4];
  wire::put_f32(p, 0.0f);
  const uint8_t start = static_cast<uint8_t>(MsgId::Start);
  const uint16_t h = eelproto::kSchemaHash;
  Bytes bad[9];
  const uint8_t garbage[] = {0x07, 0x04, 0x00};
  bad[0].append(garbage, sizeof garbage);
  const uint8_t shorty[] = {0x03, 0x04, 0x01, 0x00};
  bad[1].append(shorty, sizeof shorty);
  uint8_t big[100];
  memset(big, 0x04, sizeof big);
  bad[2].append(big, sizeof big);
  bad[2].append(garbage + 2, 1);
  bad[3] = raw_frame(h, start, 1, nullptr, 0, Spoil::Crc16);                 // CRC-16
  bad[4] = raw_frame(static_cast<uint16_t>(h + 1), start, 2, nullptr, 0);    // schema
  bad[5] = raw_frame(h, 0x44, 3, nullptr, 0);                                // unknown id
  bad[6] = raw_frame(h, start, 4, p, 4);                                     // length
  bad[7] = raw_frame(h, start, 5, nullptr, 0, Spoil::Crc32);                 // CRC-32
  bad[8] = frame_of(eelproto::Ack{start, 5}, 6);                             // direction
  for (const Bytes& x : bad) b.feed(x);
  b.run(100000);
  const LinkCounters& c = b.robot.counters();
  CHECK_EQ(c.bad_cobs, 1);
  CHECK_EQ(c.bad_short, 1);
  CHECK_EQ(c.bad_oversize, 1);
  CHECK_EQ(c.bad_crc, 1);
  CHECK_EQ(c.bad_schema, 1);
  CHECK_EQ(c.bad_unknown_id, 1);
  CHECK_EQ(c.bad_length, 1);
  CHECK_EQ(c.bad_crc32, 1);
  CHECK_EQ(c.bad_direction, 1);
  CHECK_EQ(c.frames_ok, 0);
  CHECK_EQ(b.last_telemetry.frames_bad, 9);
  CHECK(b.robot.state() == State::Idle);
  CHECK_EQ(b.acks + b.refusals, 0);
}

TEST(offset_change_while_running_is_rate_limited) {
  Bench b;
  b.send(eelproto::Start{});
  b.run(100000);
  b.send(offset(0.6f));
  b.run(100000);
  CHECK_NEAR(b.robot.gait().offset_rad(), 0.2, 1e-5);  // default 2 rad/s
  b.run(100000);
  b.send(offset(0.6f));
  b.run(200000);
  CHECK_NEAR(b.robot.gait().offset_rad(), 0.6, 1e-6);
}

TEST(pd_gains_from_a_message_drive_the_joint_torques_and_become_the_gain_settings) {
  Bench b;
  eelproto::SetGains g;
  g.kp_nm_per_rad = 2.0f;
  g.kd_nms_per_rad = 0.0f;
  g.torque_limit_nm = 0.3f;
  b.send(g);
  CHECK_EQ(b.acks, 1);
  const float phi[cfg::kJoints] = {0.1f, -0.1f, 0.0f, 0.5f}, phid[cfg::kJoints] = {};
  float u[cfg::kJoints];
  b.robot.joint_torques(phi, phid, u);
  CHECK_NEAR(u[0], -0.2, 1e-6);
  CHECK_NEAR(u[1], 0.2, 1e-6);
  CHECK_EQ(u[3], -0.3f);  // clamped
  CHECK_EQ(b.robot.settings().kp_nm_per_rad, 2.0f);
  CHECK((b.robot.flags() & bit(eelproto::Flags::SettingsUnsaved)) != 0);
}

TEST(the_gait_starts_when_start_is_handled_not_at_the_control_update_before) {
  Bench b;  // control updates every 10 ms from 0
  eelproto::SetGait g = eelproto::defaults<eelproto::SetGait>();
  g.omega_rad_s = 3.0f;
  b.send(g);
  b.run(25000);  // Start arrives 5 ms after the update at 20 ms
  b.send(eelproto::Start{});
  b.run(5000);  // the next update, at 30 ms
  CHECK_NEAR(b.robot.gait().phase_rad(), 3.0 * 0.005, 1e-6);
}

TEST(a_flood_of_commands_computes_the_gait_once_per_control_update) {
  Bench b;
  b.send(eelproto::Start{});
  const uint16_t updates0 = b.robot.control_updates(), gaits0 = b.robot.gait().updates();
  for (int k = 0; k < 100; ++k) {
    for (int i = 0; i < 20; ++i) b.send(gait(0.2f + 0.01f * i));  // 20 commands a millisecond
    b.run(1000);
  }
  const uint16_t updates = static_cast<uint16_t>(b.robot.control_updates() - updates0);
  CHECK_EQ(updates, 10);
  CHECK_EQ(static_cast<uint16_t>(b.robot.gait().updates() - gaits0), updates);
  CHECK_EQ(b.acks, 2001);
}

TEST(settings_are_read_set_saved_and_come_back_after_a_reset) {
  Bench b;
  b.set(SettingKey::TrimUs, 1, -60.0f);
  b.set(SettingKey::Reversed, 2, 1.0f);
  CHECK_EQ(b.acks, 2);
  b.send(eelproto::GetSetting{static_cast<uint8_t>(SettingKey::TrimUs), 1});
  CHECK_EQ(b.last_setting.value, -60.0f);
  b.run(20000);
  CHECK_EQ(b.robot.pulse_us()[1], 1440);  // straight: the centre moved by the trim
  CHECK((b.robot.flags() & bit(eelproto::Flags::SettingsUnsaved)) != 0);
  b.send(eelproto::SaveSettings{});
  CHECK_EQ(b.acks, 3);
  CHECK_EQ(b.robot.flags() & bit(eelproto::Flags::SettingsUnsaved), 0);
  b.boot(static_cast<uint8_t>(eelproto::ResetFlags::External));
  CHECK(b.robot.settings_source() == eelproto::SettingsSource::Eeprom);
  CHECK_EQ(b.robot.settings().trim_us[1], -60);
  CHECK_EQ(b.robot.settings().reversed[2], 1);
  b.send(eelproto::DefaultSettings{});
  CHECK_EQ(b.robot.settings().trim_us[1], 0);
}

TEST(settings_are_not_changed_or_saved_while_running) {
  Bench b;
  b.send(eelproto::Start{});
  b.set(SettingKey::TrimUs, 0, 10.0f);
  CHECK_EQ(b.last_refuse_reason, why(eelproto::RefuseReason::NotWhileRunning));
  b.send(eelproto::SaveSettings{});
  b.send(eelproto::DefaultSettings{});
  CHECK_EQ(b.refusals, 3);
  CHECK_EQ(b.saves, 0);
  CHECK_EQ(b.robot.settings().trim_us[0], 0);
}

TEST(an_eeprom_that_does_not_take_the_write_refuses_the_save) {
  Bench b;
  b.eeprom_fails = true;
  b.set(SettingKey::RadioId, 0, 7.0f);
  b.send(eelproto::SaveSettings{});
  CHECK_EQ(b.refusals, 1);
  CHECK_EQ(b.last_refuse_reason, why(eelproto::RefuseReason::StorageFailed));
  CHECK((b.robot.flags() & bit(eelproto::Flags::SettingsUnsaved)) != 0);
}

TEST(a_corrupt_eeprom_boots_the_defaults_and_status_says_so) {
  Bench b;
  b.set(SettingKey::TrimUs, 0, 40.0f);
  b.send(eelproto::SaveSettings{});
  // One bit of the stored settings in each slot (the save went to slot 1, slot 0 has the defaults).
  b.eeprom[settings_slot_address(0) + 9] ^= 0x01;
  b.eeprom[settings_slot_address(1) + 9] ^= 0x01;
  b.boot(static_cast<uint8_t>(eelproto::ResetFlags::Watchdog));
  CHECK(b.robot.settings_source() == eelproto::SettingsSource::Corrupt);
  CHECK_EQ(b.robot.settings().trim_us[0], 0);
  b.send(eelproto::GetStatus{});
  b.run(10000);
  CHECK_EQ(b.last_status.settings_source, static_cast<uint8_t>(eelproto::SettingsSource::Corrupt));
  CHECK_EQ(b.last_status.reset_flags, static_cast<uint8_t>(eelproto::ResetFlags::Watchdog));
}

TEST(without_feedback_the_robot_says_so_and_measures_nothing) {
  Bench b;
  b.run(100000);
  CHECK_EQ(b.last_telemetry.flags & bit(eelproto::Flags::JointFeedback), 0);
  for (int j = 0; j < cfg::kJoints; ++j) CHECK_EQ(b.last_telemetry.phi_mrad[j], -32768);
  CHECK(b.robot.wants_adc());  // for the battery only (the default divider)
}

TEST(with_feedback_the_measured_angles_go_into_telemetry) {
  Bench b;
  b.set(SettingKey::JointFeedback, 0, 1.0f);
  b.set(SettingKey::AdcCentre, 0, 500.0f);
  b.set(SettingKey::Reversed, 1, 1.0f);
  b.adc[0] = 630;  // 130 counts above the centre: 130 / 130.4 rad
  b.adc[1] = 612;  // 100 above, reversed
  b.run(100000);
  CHECK(b.robot.wants_adc());
  CHECK((b.last_telemetry.flags & bit(eelproto::Flags::JointFeedback)) != 0);
  CHECK_EQ(b.last_telemetry.phi_mrad[0], 997);
  CHECK_EQ(b.last_telemetry.phi_mrad[1], -767);
  CHECK_EQ(b.last_telemetry.phi_mrad[2], 0);
}

TEST(the_robots_pd_with_kp_equal_to_the_servo_stiffness_and_no_kd_commands_the_reference) {
  // Cross-check of the two modes: phi + kp (alpha - phi) / k_s = alpha when kp = k_s, kd = 0.
  Bench open, closed;
  eelproto::SetGains g{2.5f, 0.0f, 10.0f};
  Bench* both[] = {&open, &closed};
  for (Bench* b : both) {
    b->send(g);
    b->send(gait(0.7f));
    b->send(eelproto::Start{});
  }
  closed.set(SettingKey::JointFeedback, 0, 1.0f);  // refused while running: set it first
  closed.send(eelproto::Stop{});
  closed.set(SettingKey::JointFeedback, 0, 1.0f);
  closed.set(SettingKey::ServoStiffnessNmPerRad, 0, 2.5f);
  closed.send(eelproto::Start{});
  open.send(eelproto::Stop{});
  open.send(eelproto::Start{});
  for (int k = 0; k < 100; ++k) {
    for (int j = 0; j < cfg::kJoints; ++j) closed.adc[j] = static_cast<uint16_t>(400 + 37 * j + k);
    open.run(10000);
    closed.run(10000);
    open.send(offset(0.0f));
    closed.send(offset(0.0f));
    for (int j = 0; j < cfg::kJoints; ++j) {
      CHECK(abs(open.robot.pulse_us()[j] - closed.robot.pulse_us()[j]) <= 1);  // float rounding
    }
  }
}

TEST(the_robots_pd_damps_with_kd_over_the_servo_stiffness) {
  Bench b;
  b.send(eelproto::SetGains{1.0f, 0.05f, 10.0f});
  b.set(SettingKey::JointFeedback, 0, 1.0f);
  b.set(SettingKey::ServoStiffnessNmPerRad, 0, 0.5f);
  // Idle and straight (alpha = 0): joint 1 moving at a steady rate. The command is
  // phi + (kp (0 - phi) + kd (0 - phi_dot)) / k_s with the filtered rate estimate.
  for (int k = 0; k < 50; ++k) {
    b.adc[0] = static_cast<uint16_t>(512 + 2 * k);  // 2 counts per 10 ms: 1.534 rad/s
    b.run(10000);
  }
  const double phi = 98.0 / 130.4, rate = 2.0 / 130.4 / 0.01;
  const double command = phi + (1.0 * (0.0 - phi) + 0.05 * (0.0 - rate)) / 0.5;
  CHECK_NEAR(b.robot.joints().phi_rad()[0], phi, 1e-6);
  CHECK_NEAR(b.robot.joints().phi_dot_rad_s()[0], rate, 1e-4);
  CHECK(abs(b.robot.pulse_us()[0] - static_cast<int>(floor(1500 + 636.6 * command + 0.5))) <= 1);
}

TEST(low_battery_stops_the_robot_and_it_recovers_above_the_hysteresis) {
  Bench b;
  b.set(SettingKey::BatteryDivider, 0, 3.0f);  // 7.5 V at 2.5 V: 512 counts
  b.run(100000);
  CHECK_NEAR(b.robot.battery().volts(), 512 * 5.0 / 1024 * 3.0, 1e-5);
  b.send(eelproto::Start{});
  b.run(500000);
  const uint16_t low = 420;  // 6.15 V, below 6.4
  b.adc[cfg::kBatteryInput] = low;
  b.run_alive(600000);  // filtered over 1 s, the drop crosses 6.4 V only after 1.7 s
  CHECK(b.robot.state() == State::Running);
  b.run_alive(1200000);
  CHECK(b.robot.state() == State::LowBattery);
  CHECK_EQ(b.last_telemetry.state, static_cast<uint8_t>(State::LowBattery));
  b.send(eelproto::Start{});
  CHECK_EQ(b.last_refuse_reason, why(eelproto::RefuseReason::LowBattery));
  b.adc[cfg::kBatteryInput] = 470;  // 6.88 V: above the stop, below 6.4 + 0.6
  b.run(5000000);
  CHECK(b.robot.state() == State::LowBattery);
  CHECK_EQ(b.max_abs_alpha(), 0.0f);
  b.adc[cfg::kBatteryInput] = 490;  // 7.18 V
  b.run(6000000);
  CHECK(b.robot.state() == State::Idle);
  b.send(eelproto::GetStatus{});
  b.run(10000);
  CHECK_NEAR(b.last_status.battery_v, 490 * 5.0 / 1024 * 3.0, 0.01);
  CHECK((b.last_status.flags & bit(eelproto::Flags::BatterySense)) != 0);
}

// ---------------------------------------------------------------- replays and the link watchdog

TEST(a_replayed_last_frame_is_answered_but_does_not_hold_off_the_fade_or_failsafe) {
  Bench b;
  b.send(gait(1.5f));
  b.send(eelproto::Start{});
  const Bytes last = frame_of(offset(0.1f), b.seq++);
  b.feed(last);
  const int acks = b.acks;
  // A stuck radio repeats the last frame every 50 ms for 3 s.
  bool faded = false;
  for (int k = 0; k < 60; ++k) {
    b.run(50000);
    b.feed(last);
    faded = faded || (b.last_telemetry.flags & bit(eelproto::Flags::Fading)) != 0;
    if (k == 18) CHECK(b.max_abs_alpha() < 1e-6f);  // 0.95 s after the last new frame: straight
  }
  CHECK(faded);
  CHECK(b.robot.state() == State::Failsafe);
  CHECK_EQ(b.acks, acks + 60);  // every copy answered as the first was
  CHECK_EQ(b.robot.counters().duplicates, 60);
}

TEST(only_a_sequence_number_ahead_of_the_last_feeds_the_link_watchdog) {
  Bench b;
  b.send(eelproto::Start{});
  b.run(500000);
  const uint32_t fed_at = b.robot.watchdog().last_valid_us();
  b.feed(frame_of(offset(0.2f), static_cast<uint8_t>(b.seq - 1)));  // same number, new content
  b.feed(frame_of(offset(0.2f), static_cast<uint8_t>(b.seq - 5)));  // behind: an old frame
  CHECK_EQ(b.robot.watchdog().last_valid_us(), fed_at);
  b.feed(frame_of(offset(0.2f), b.seq++));  // the next number: the host is there
  CHECK_EQ(b.robot.watchdog().last_valid_us(), b.now);
}

// ---------------------------------------------------------------- power-safe settings

namespace {
struct Assign {
  SettingKey key;
  uint8_t index;
  float value;
};
bool same_settings(const eelproto::Settings& a, const eelproto::Settings& b) {
  uint8_t x[eelproto::kSettingsBytes], y[eelproto::kSettingsBytes];
  eelproto::settings_pack(a, x);
  eelproto::settings_pack(b, y);
  return memcmp(x, y, sizeof x) == 0;
}
// A bench booted from this EEPROM with these settings changed through SetSetting.
void prepare(Bench& b, const uint8_t* eeprom, const Assign* a, size_t n) {
  memcpy(b.eeprom, eeprom, sizeof b.eeprom);
  b.boot(kPowerOn);
  for (size_t k = 0; k < n; ++k) {
    b.send(eelproto::SetSetting{static_cast<uint8_t>(a[k].key), a[k].index, a[k].value});
  }
}
}  // namespace

TEST(a_reset_at_any_byte_of_a_save_boots_the_old_or_the_new_settings) {
  // Two saves one after the other (the first writes slot 1, the second overwrites slot 0 with the
  // generation after), each cut while programming each of its bytes, that byte left erased, as
  // it was, garbage or as meant.
  const Assign first[] = {{SettingKey::TrimUs, 0, -40.0f}, {SettingKey::TrimUs, 3, 25.0f},
                          {SettingKey::KpNmPerRad, 0, 2.5f}, {SettingKey::BatteryDivider, 0, 2.9f},
                          {SettingKey::RadioId, 0, 4242.0f}};
  const Assign second[] = {{SettingKey::KpNmPerRad, 0, 7.0f}, {SettingKey::TrimUs, 2, 123.0f}};
  const Assign* saves[] = {first, second};
  const size_t counts[] = {sizeof first / sizeof first[0], sizeof second / sizeof second[0]};
  Bench ref;  // its EEPROM: the settings before the save
  int cuts = 0;
  for (int k = 0; k < 2; ++k) {
    const eelproto::Settings old_settings = ref.robot.settings();
    Bench full;  // the whole save, for the new settings and the bytes it programs
    prepare(full, ref.eeprom, saves[k], counts[k]);
    const int writes_before = full.eeprom_writes;
    const int acks_before = full.acks;
    full.send(eelproto::SaveSettings{});
    CHECK_EQ(full.acks, acks_before + 1);
    const eelproto::Settings new_settings = full.robot.settings();
    CHECK(!same_settings(old_settings, new_settings));
    const int n_bytes = full.eeprom_writes - writes_before;
    CHECK(n_bytes > 8);
    for (int cut = 0; cut < n_bytes; ++cut) {
      for (int damage = 0; damage < 4; ++damage) {
        Bench b;
        prepare(b, ref.eeprom, saves[k], counts[k]);
        const Bytes save = frame_of(eelproto::SaveSettings{}, b.seq++);
        for (size_t i = 0; i < save.n; ++i) b.robot.on_rx_byte(save.data[i], b.now);
        const int start = b.eeprom_writes;
        while (b.eeprom_writes - start <= cut) {
          CHECK(b.robot.settings_writer().step(b) == SettingsWriter::Step::Writing);
        }
        // the power fails while byte `cut` is being programmed
        const uint8_t left[] = {0xFF, ref.eeprom[b.last_write_address], 0x5A,
                                b.eeprom[b.last_write_address]};
        b.eeprom[b.last_write_address] = left[damage];
        b.boot(kPowerOn);
        CHECK(b.robot.settings_source() == eelproto::SettingsSource::Eeprom);
        const bool is_old = same_settings(b.robot.settings(), old_settings);
        const bool is_new = same_settings(b.robot.settings(), new_settings);
        CHECK(is_old || is_new);
        CHECK(!b.robot.settings_lost());
        if (cut < n_bytes - 4) CHECK(is_old);  // the CRC-32 goes in last
        ++cuts;
      }
    }
    memcpy(ref.eeprom, full.eeprom, sizeof ref.eeprom);
    ref.boot(kPowerOn);
    CHECK(same_settings(ref.robot.settings(), new_settings));
  }
  CHECK(cuts > 4 * 2 * 10);
}

TEST(with_no_valid_slot_the_defaults_keep_the_battery_stop_and_start_waits_for_the_host) {
  Bench b;
  memset(b.eeprom, 0xFF, sizeof b.eeprom);  // blank (also what a corrupt pair of slots gives)
  b.boot(kPowerOn);
  CHECK(b.robot.settings_source() == eelproto::SettingsSource::Blank);
  CHECK(b.robot.settings().battery_divider > 0.0f);  // the low-voltage stop is armed
  b.run(100000);
  CHECK((b.last_telemetry.flags & bit(eelproto::Flags::SettingsLost)) != 0);
  CHECK((b.last_telemetry.flags & bit(eelproto::Flags::BatterySense)) != 0);
  b.send(eelproto::Start{});
  CHECK_EQ(b.last_refuse_reason, why(eelproto::RefuseReason::SettingsLost));
  CHECK(b.robot.state() == State::Idle);
  b.adc[cfg::kBatteryInput] = 300;  // 4.7 V: the stop works with the defaults
  b.run(5000000);
  CHECK(b.robot.state() == State::LowBattery);
  b.adc[cfg::kBatteryInput] = 512;
  b.run(5000000);
  CHECK(b.robot.state() == State::Idle);
  b.send(eelproto::DefaultSettings{});  // the host acknowledges the defaults
  const int acks = b.acks;
  b.send(eelproto::Start{});
  CHECK_EQ(b.acks, acks + 1);
  CHECK(b.robot.state() == State::Running);
  b.run(100000);
  CHECK_EQ(b.last_telemetry.flags & bit(eelproto::Flags::SettingsLost), 0);
}

TEST(a_successful_save_also_acknowledges_lost_settings) {
  Bench b;
  memset(b.eeprom, 0xFF, sizeof b.eeprom);
  b.boot(kPowerOn);
  b.send(eelproto::SaveSettings{});
  CHECK(!b.robot.settings_lost());
  b.boot(kPowerOn);
  CHECK(b.robot.settings_source() == eelproto::SettingsSource::Eeprom);
  CHECK(!b.robot.settings_lost());
}

// ---------------------------------------------------------------- reset cause behind a bootloader

TEST(a_cleared_mcusr_is_read_from_the_watchdog_mark_and_the_reset_record) {
  using eelproto::ResetFlags;
  ResetRecord r{0, 0};  // RAM as a power-on leaves it: the record does not check out
  CHECK_EQ(infer_reset_flags(0, false, r), static_cast<uint8_t>(ResetFlags::PowerOn));
  count_reset(r, static_cast<uint8_t>(ResetFlags::PowerOn));  // the record now checks out
  CHECK_EQ(infer_reset_flags(0, true, r), static_cast<uint8_t>(ResetFlags::Watchdog));
  CHECK_EQ(infer_reset_flags(0, false, r), 0);  // the reset pin or a brown-out: unknown
  const uint8_t ext = static_cast<uint8_t>(ResetFlags::External);
  CHECK_EQ(infer_reset_flags(ext, true, r), ext);  // bits MCUSR kept are taken as they are
}

// Replies first (docs/firmware.md, "Link"): an answer to a command may use the whole transmit
// queue; Telemetry and the periodic Status go in only with CommandLink::kReplyRoomBytes left free,
// else at a later control update.

TEST(the_link_counts_each_frame_the_robot_sends_at_its_encoded_length) {
  CHECK_EQ(CommandLink::frame_bytes(eelproto::Ack::kPayloadBytes), frame_of(eelproto::Ack{}, 0).n);
  CHECK_EQ(CommandLink::frame_bytes(eelproto::Refuse::kPayloadBytes),
           frame_of(eelproto::Refuse{}, 0).n);
  CHECK_EQ(CommandLink::frame_bytes(eelproto::Version::kPayloadBytes),
           frame_of(eelproto::Version{}, 0).n);
  CHECK_EQ(CommandLink::frame_bytes(eelproto::Setting::kPayloadBytes),
           frame_of(eelproto::Setting{}, 0).n);
  CHECK_EQ(CommandLink::frame_bytes(eelproto::Telemetry::kPayloadBytes),
           frame_of(eelproto::Telemetry{}, 0).n);
  CHECK_EQ(CommandLink::frame_bytes(eelproto::Status::kPayloadBytes),
           frame_of(eelproto::Status{}, 0).n);
}

TEST(a_periodic_frame_fits_only_when_it_leaves_room_for_any_reply) {
  CommandLink link;
  link.reset(0);
  const uint16_t telemetry = frame_of(eelproto::Telemetry{}, 0).n;
  const uint16_t largest_reply = frame_of(eelproto::Status{}, 0).n;
  CHECK(CommandLink::kReplyRoomBytes >= largest_reply);
  while (link.tx().space() > telemetry + CommandLink::kReplyRoomBytes) link.tx().push(0x55);
  CHECK(link.periodic_fits(eelproto::Telemetry::kPayloadBytes));
  link.tx().push(0x55);
  CHECK(!link.periodic_fits(eelproto::Telemetry::kPayloadBytes));
  // A reply still fits there, down to the last byte of the queue.
  link.ack(static_cast<uint8_t>(MsgId::Start), 0);
  CHECK_EQ(link.counters().tx_dropped, 0);
  while (link.tx().space() > 0) link.tx().push(0x55);
  link.ack(static_cast<uint8_t>(MsgId::Start), 1);
  CHECK_EQ(link.counters().tx_dropped, 1);
}

TEST(the_boot_burst_is_answered_in_full_and_the_first_telemetry_waits_for_the_replies_room) {
  // The host's burst at boot (Hello, then the configuration) while the UART is still busy: the
  // Version takes 22 bytes, the first Telemetry (due at the first update) would take 58 and leave
  // the four Acks no room under the old rule. Now the Telemetry waits and every Ack is queued.
  Bench b;
  b.uart_stalled = true;
  b.send(eelproto::Hello{});
  b.run(10000);  // the first control update: the Telemetry is due
  CHECK_EQ(b.robot.tx().size(), frame_of(eelproto::Version{}, 0).n);
  b.send(eelproto::defaults<eelproto::SetGains>());
  b.send(gait(0.3f));
  b.send(offset(0.1f));
  b.send(eelproto::Start{});
  CHECK_EQ(b.robot.counters().tx_dropped, 0);
  b.uart_stalled = false;
  b.drain();
  CHECK_EQ(b.versions, 1);
  CHECK_EQ(b.acks, 4);
  CHECK_EQ(b.telemetry, 0);
  b.run(10000);  // the next update sends the Telemetry that waited, with its figures
  CHECK_EQ(b.telemetry, 1);
  CHECK_EQ(b.last_telemetry.time_us, 20000u);
  CHECK(b.last_telemetry.state == static_cast<uint8_t>(State::Running));
  b.run(80000);  // and the cadence is kept: the next one at 100 ms, not 110
  CHECK_EQ(b.telemetry, 2);
  CHECK_EQ(b.last_telemetry.time_us, 100000u);
  CHECK_EQ(b.robot.counters().tx_dropped, 0);
}

TEST(replies_fill_the_whole_queue_and_the_periodic_frames_wait_uncounted_until_it_drains) {
  Bench b;
  b.run(10000);
  CHECK_EQ(b.telemetry, 1);
  b.uart_stalled = true;
  const uint16_t version = frame_of(eelproto::Version{}, 0).n;
  const int fit = CommandLink::TxQueue::kCapacity / version;
  for (int k = 0; k <= fit; ++k) b.send(eelproto::Hello{});
  CHECK_EQ(b.robot.counters().tx_dropped, 1);  // the one Version the replies had no room for
  b.send(eelproto::Start{});  // an Ack still takes what is left
  CHECK_EQ(b.robot.tx().size(), fit * version + frame_of(eelproto::Ack{}, 0).n);
  b.run(200000);  // Telemetry due at 100 and 200 ms, Status at 50 ms: all wait, none dropped
  CHECK_EQ(b.robot.counters().tx_dropped, 1);
  b.uart_stalled = false;
  b.drain();
  CHECK_EQ(b.versions, fit);
  CHECK_EQ(b.acks, 1);
  CHECK_EQ(b.telemetry, 1);
  CHECK_EQ(b.statuses, 0);
  b.run(10000);  // the Telemetry that waited (once, not once per missed period)
  CHECK_EQ(b.telemetry, 2);
  b.run(10000);  // then the Status (both at once would not leave the replies their room)
  CHECK_EQ(b.statuses, 1);
  CHECK_EQ(b.telemetry, 2);
  CHECK_EQ(b.last_status.tx_dropped, 1);
}

TEST(the_status_a_host_asks_for_is_a_reply_and_takes_the_room_a_periodic_frame_leaves) {
  Bench b;
  b.run(10000);
  b.uart_stalled = true;
  b.send(eelproto::Hello{});  // 22 bytes queued: a periodic Status (50 + 64 free) would wait
  CHECK(!b.robot.tx().empty());
  b.send(eelproto::GetStatus{});
  b.run(10000);
  b.uart_stalled = false;
  b.drain();
  CHECK_EQ(b.statuses, 1);
  CHECK_EQ(b.last_status.time_us, 20000u);
  CHECK_EQ(b.robot.counters().tx_dropped, 0);
}
