#include <math.h>

#include "check.h"
#include "frames.h"
#include "robot.h"

namespace {
using eelproto::MsgId;
using eelproto::State;

// The robot with a clock and a decoder for what it sends back.
struct Bench {
  Robot robot;
  uint32_t now = 0;
  uint8_t seq = 0;
  FrameDecoder out_decoder;
  LinkCounters out_counters{};
  int acks = 0, refusals = 0, telemetry = 0, versions = 0;
  uint8_t last_refuse_reason = 0;
  eelproto::Telemetry last_telemetry{};

  explicit Bench(uint32_t t0 = 0) : now(t0) { robot.reset(t0); }

  void feed(const Bytes& b) {
    for (size_t i = 0; i < b.n; ++i) robot.on_rx_byte(b.data[i], now);
    drain();
  }
  template <class M>
  void send(const M& m) { feed(frame_of(m, seq++)); }

  // Run the main loop for `us` microseconds in 1 ms passes.
  void run(uint32_t us) {
    for (uint32_t t = 0; t < us; t += 1000) {
      now += 1000;
      robot.service(now);
      if (robot.control_due(now)) robot.control_update(now);
      drain();
    }
  }
  void drain() {
    Robot::TxQueue& tx = robot.tx();
    while (!tx.empty()) {
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
        case MsgId::Version: ++versions; break;
        default: break;
      }
    }
  }
  float max_abs_alpha() const {
    float m = 0.0f;
    for (int j = 0; j < cfg::kJoints; ++j) m = fmaxf(m, fabsf(robot.gait().alpha_rad()[j]));
    return m;
  }
};

eelproto::SetOffset offset(float v) {
  eelproto::SetOffset m;
  m.offset_rad = v;
  return m;
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

TEST(hello_is_answered_with_the_version) {
  Bench b;
  b.send(eelproto::Hello{});
  CHECK_EQ(b.versions, 1);
}

TEST(out_of_range_gait_is_refused_and_changes_nothing) {
  Bench b;
  eelproto::SetGait g = eelproto::defaults<eelproto::SetGait>();
  g.amplitude_rad = 2.0f;
  b.send(g);
  CHECK_EQ(b.refusals, 1);
  CHECK_EQ(b.last_refuse_reason, static_cast<uint8_t>(eelproto::RefuseReason::OutOfRange));
  CHECK_EQ(b.robot.gait().targets().omega_rad_s, eelproto::defaults<eelproto::SetGait>().omega_rad_s);
}

TEST(nan_offset_is_refused_as_not_finite) {
  Bench b;
  b.send(offset(nanf("")));
  CHECK_EQ(b.refusals, 1);
  CHECK_EQ(b.last_refuse_reason, static_cast<uint8_t>(eelproto::RefuseReason::NotFinite));
}

TEST(message_meant_for_the_host_is_refused_as_unsupported) {
  Bench b;
  b.send(eelproto::Telemetry{});
  CHECK_EQ(b.refusals, 1);
  CHECK_EQ(b.last_refuse_reason, static_cast<uint8_t>(eelproto::RefuseReason::Unsupported));
}

TEST(no_valid_frame_for_one_second_enters_failsafe_and_straightens) {
  Bench b;
  b.send(eelproto::Start{});
  b.run(999000);
  CHECK(b.robot.state() == State::Running);
  b.run(1000);
  CHECK(b.robot.state() == State::Failsafe);
  CHECK_EQ(b.last_telemetry.state, static_cast<uint8_t>(State::Failsafe));
  b.run(1500000);  // amplitude 0.5 and rates >= 1 rad/s: straight well within 1.5 s
  CHECK_EQ(b.max_abs_alpha(), 0.0f);
  CHECK_EQ(b.last_telemetry.state, static_cast<uint8_t>(State::Failsafe));
}

TEST(failsafe_straightening_has_no_jump) {
  Bench b;
  eelproto::SetGait g = eelproto::defaults<eelproto::SetGait>();
  g.amplitude_rad = 1.0f;
  g.amplitude_rate_rad_s = 0.1f;  // slow: straightening must still be at least 1 rad/s
  g.offset_rate_rad_s = 0.0f;
  b.send(g);
  b.send(offset(0.0f));
  b.send(eelproto::Start{});
  b.run(900000);
  b.send(offset(0.0f));
  b.run(900000);  // link lost 0.9 s ago; failsafe in 0.1 s
  float prev[cfg::kJoints];
  for (int j = 0; j < cfg::kJoints; ++j) prev[j] = b.robot.gait().alpha_rad()[j];
  float worst = 0.0f;
  for (int k = 0; k < 300; ++k) {
    b.run(10000);
    for (int j = 0; j < cfg::kJoints; ++j) {
      worst = fmaxf(worst, fabsf(b.robot.gait().alpha_rad()[j] - prev[j]));
      prev[j] = b.robot.gait().alpha_rad()[j];
    }
  }
  CHECK(b.robot.state() == State::Failsafe);
  CHECK_EQ(b.max_abs_alpha(), 0.0f);  // 0.18 rad of amplitude gone at >= 1 rad/s within 3 s
  CHECK(worst < 0.05f);
}

TEST(frames_every_300ms_keep_the_robot_running) {
  Bench b;
  b.send(eelproto::Start{});
  for (int k = 0; k < 20; ++k) {
    b.run(300000);
    b.send(offset(0.1f));
  }
  CHECK(b.robot.state() == State::Running);
}

TEST(failsafe_fires_one_second_after_the_last_frame_across_the_micros_wrap) {
  Bench b(0xFFFFFFFFu - 400000u);
  b.send(eelproto::Start{});
  b.run(999000);  // crosses the wrap 0.4 s in
  CHECK(b.robot.state() == State::Running);
  b.run(1000);
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
  b.run(900000);
  b.send(eelproto::Stop{});
  b.run(900000);
  CHECK(b.robot.state() == State::Idle);
  CHECK_EQ(b.max_abs_alpha(), 0.0f);
}

TEST(telemetry_comes_every_100ms_with_time_and_counters) {
  Bench b;
  b.run(1000000);
  CHECK(b.telemetry >= 10 && b.telemetry <= 11);
  CHECK_EQ(b.last_telemetry.time_us, 1000000u);
  CHECK_EQ(b.last_telemetry.frames_bad, 0);
}

TEST(sequence_gaps_count_lost_frames_and_duplicates_are_ignored) {
  Bench b;
  b.feed(frame_of(offset(0.1f), 10));
  b.feed(frame_of(offset(0.2f), 13));  // 11 and 12 lost
  b.feed(frame_of(offset(0.3f), 13));  // radio retry of 13: ignored
  CHECK_EQ(b.robot.counters().lost, 2);
  CHECK_EQ(b.robot.counters().duplicates, 1);
  CHECK_EQ(b.acks, 2);
  CHECK_EQ(b.robot.gait().targets().offset_rad, 0.0f);  // idle: offset target stays 0
}

TEST(every_kind_of_bad_frame_is_counted_and_never_acted_on) {
  Bench b;
  uint8_t p[4];
  wire::put_f32(p, 0.0f);
  const uint8_t start = static_cast<uint8_t>(MsgId::Start);
  const uint16_t h = eelproto::kSchemaHash;
  Bytes bad[7];
  const uint8_t garbage[] = {0x07, 0x04, 0x00};
  bad[0].append(garbage, sizeof garbage);
  const uint8_t shorty[] = {0x03, 0x04, 0x01, 0x00};
  bad[1].append(shorty, sizeof shorty);
  uint8_t big[100];
  memset(big, 0x04, sizeof big);
  bad[2].append(big, sizeof big);
  bad[2].append(garbage + 2, 1);
  bad[3] = raw_frame(h, start, 1, nullptr, 0, true);                          // CRC
  bad[4] = raw_frame(static_cast<uint16_t>(h + 1), start, 2, nullptr, 0);     // schema
  bad[5] = raw_frame(h, 0x44, 3, nullptr, 0);                                 // unknown id
  bad[6] = raw_frame(h, start, 4, p, 4);                                      // length
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
  CHECK_EQ(c.frames_ok, 0);
  CHECK_EQ(b.last_telemetry.frames_bad, 7);
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
  b.run(300000);
  CHECK_NEAR(b.robot.gait().offset_rad(), 0.6, 1e-6);
}

TEST(pd_gains_from_a_message_drive_the_joint_torques) {
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
