// The native library's C API (hal/native/eel_native.h) as a caller sees it: the loop's bounds
// under a flood, resets and their count, the EEPROM, the analog inputs, faults counted.
#include <string.h>

#include "app.h"
#include "check.h"
#include "eel_native.h"
#include "frames.h"
#include "settings_codec.h"

namespace {
using eelproto::MsgId;

// Received frames, decoded.
struct Inbox {
  FrameDecoder decoder;
  LinkCounters counters{};
  int acks = 0, refusals = 0, telemetry = 0, statuses = 0;
  uint32_t last_telemetry_us = 0, longest_telemetry_gap_us = 0;
  eelproto::Status last_status{};
  void take(EelFw* fw) {
    uint8_t buf[512];
    for (size_t n; (n = eel_take(fw, buf, sizeof buf)) > 0;) {
      for (size_t i = 0; i < n; ++i) {
        if (!decoder.push(buf[i], counters)) continue;
        const Frame& f = decoder.frame();
        if (f.msg_id == static_cast<uint8_t>(MsgId::Ack)) ++acks;
        if (f.msg_id == static_cast<uint8_t>(MsgId::Refuse)) ++refusals;
        if (f.msg_id == static_cast<uint8_t>(MsgId::Status)) {
          ++statuses;
          eelproto::unpack(last_status, f.payload);
        }
        if (f.msg_id == static_cast<uint8_t>(MsgId::Telemetry)) {
          eelproto::Telemetry t;
          eelproto::unpack(t, f.payload);
          if (telemetry++ > 0 && t.time_us - last_telemetry_us > longest_telemetry_gap_us) {
            longest_telemetry_gap_us = t.time_us - last_telemetry_us;
          }
          last_telemetry_us = t.time_us;
        }
      }
    }
  }
};

template <class M>
void send(EelFw* fw, const M& m, uint8_t seq) {
  const Bytes b = frame_of(m, seq);
  CHECK_EQ(eel_feed(fw, b.data, b.n), b.n);
}

EelStatus status_of(EelFw* fw) {
  EelStatus s;
  eel_status(fw, &s);
  return s;
}
}  // namespace

TEST(one_robot_pass_decodes_at_most_four_bytes) {
  EelFw* fw = eel_create(0);
  const Bytes start = frame_of(eelproto::Start{}, 0);  // 12 bytes
  eel_feed(fw, start.data, start.n);
  eel_pass(fw, 100);
  eel_pass(fw, 200);
  CHECK_EQ(status_of(fw).state, 0);  // 8 bytes read: not yet a frame
  eel_pass(fw, 300);
  CHECK_EQ(status_of(fw).state, 1);
  eel_destroy(fw);
}

TEST(under_a_line_rate_flood_of_commands_every_control_update_comes_on_time) {
  // The robot's loop with simulated time: a pass every 100 us, bytes arriving at 57600 baud
  // (173.6 us each, back to back) for 3 s. The native build has no CPU time, so this checks the
  // loop's structure: an update at every 10 ms deadline, the gait computed once per update,
  // replies and telemetry flowing. simavr measures the time (test_firmware_avr_image.py).
  EelFw* fw = eel_create(0);
  Inbox inbox;
  Bytes frame;
  int sent = 0;
  size_t at = 0;
  double next_byte_us = 0.0;
  uint16_t updates_before = 0;
  for (uint32_t now = 100; now <= 3000000; now += 100) {
    while (next_byte_us <= now) {
      if (at == 0) {  // new gaits (a new omega each time), offsets, starts: all acknowledged
        const uint8_t seq = static_cast<uint8_t>(sent);
        frame = sent % 3 == 0 ? frame_of(eelproto::SetGait{0.5f, 2.0f + 0.5f * (sent % 5), 1.0f,
                                                           0.5f, 1.0f, 2.0f},
                                         seq)
                : sent % 3 == 1 ? frame_of(eelproto::SetOffset{0.01f * (sent % 20)}, seq)
                                : frame_of(eelproto::Start{}, seq);
      }
      eel_feed(fw, frame.data + at, 1);
      next_byte_us += 1e6 / 5760.0;
      if (++at == frame.n) {
        at = 0;
        ++sent;
      }
    }
    const uint16_t before = status_of(fw).control_updates;
    eel_pass(fw, now);
    const uint16_t after = status_of(fw).control_updates;
    CHECK_EQ(after - before, now % 10000 == 0 ? 1 : 0);  // exactly at each deadline
    if (now == 100) updates_before = before;
    inbox.take(fw);
  }
  const EelStatus s = status_of(fw);
  CHECK_EQ(s.gait_updates - updates_before, s.control_updates - updates_before);
  CHECK_EQ(s.control_late_max_us, 0);
  CHECK(s.frames_ok >= sent - 1);  // all but one in flight
  CHECK_EQ(s.frames_bad, 0);
  // Every command answered but those the queue had no room for, which the robot counts.
  CHECK_EQ(inbox.acks + s.tx_dropped, s.frames_ok);
  CHECK(inbox.acks >= 0.95 * s.frames_ok);
  CHECK_EQ(inbox.telemetry, 30);
  CHECK_EQ(inbox.longest_telemetry_gap_us, 100000u);
  eel_destroy(fw);
}

TEST(reboots_count_resets_since_power_on_and_status_reports_the_cause) {
  EelFw* fw = eel_create(0);
  const uint8_t watchdog = static_cast<uint8_t>(eelproto::ResetFlags::Watchdog);
  for (int k = 0; k < 3; ++k) eel_reboot(fw, 0, watchdog);
  EelStatus s = status_of(fw);
  CHECK_EQ(s.resets, 3);
  CHECK_EQ(s.reset_flags, watchdog);
  Inbox inbox;
  send(fw, eelproto::GetStatus{}, 0);
  eel_tick(fw, 10000, nullptr, nullptr, nullptr);
  inbox.take(fw);
  CHECK_EQ(inbox.last_status.resets, 3);
  CHECK_EQ(inbox.last_status.reset_flags, watchdog);
  eel_reset(fw, 0);  // a power cycle
  s = status_of(fw);
  CHECK_EQ(s.resets, 0);
  CHECK_EQ(s.reset_flags, static_cast<uint8_t>(eelproto::ResetFlags::PowerOn));
  eel_destroy(fw);
}

TEST(saved_settings_survive_a_power_cycle_and_a_corrupt_eeprom_gives_the_defaults) {
  EelFw* fw = eel_create(0);
  send(fw, eelproto::SetSetting{static_cast<uint8_t>(eelproto::SettingKey::TrimUs), 4, -80.0f}, 0);
  send(fw, eelproto::SaveSettings{}, 1);
  eel_tick(fw, 10000, nullptr, nullptr, nullptr);
  eel_reset(fw, 0);
  EelOutputs out;
  eel_tick(fw, 10000, nullptr, nullptr, &out);
  CHECK_EQ(status_of(fw).settings_source, static_cast<uint8_t>(eelproto::SettingsSource::Eeprom));
  CHECK_EQ(out.pulse_us[4], 1420);
  // One bit of each slot (slot 0: the defaults it was created with; slot 1: the save).
  for (uint8_t slot = 0; slot < kSettingsSlots; ++slot) {
    const uint16_t at = static_cast<uint16_t>(settings_slot_address(slot) + 20);
    uint8_t byte;
    CHECK_EQ(eel_eeprom_read(fw, at, &byte, 1), 1u);
    byte ^= 0x40;
    eel_eeprom_write(fw, at, &byte, 1);
  }
  eel_reboot(fw, 0, static_cast<uint8_t>(eelproto::ResetFlags::External));
  eel_tick(fw, 10000, nullptr, nullptr, &out);
  CHECK_EQ(status_of(fw).settings_source, static_cast<uint8_t>(eelproto::SettingsSource::Corrupt));
  CHECK_EQ(out.pulse_us[4], 1500);
  eel_set_eeprom_failing(fw, 1);
  Inbox inbox;
  send(fw, eelproto::SaveSettings{}, 2);
  eel_tick(fw, 20000, nullptr, nullptr, nullptr);
  inbox.take(fw);
  CHECK_EQ(inbox.refusals, 1);
  eel_destroy(fw);
}

TEST(joint_angles_fed_through_the_calibration_come_back_measured) {
  EelFw* fw = eel_create(0);
  eel_set_control_period_us(fw, 0);
  send(fw, eelproto::SetSetting{static_cast<uint8_t>(eelproto::SettingKey::JointFeedback), 0, 1.0f},
       0);
  send(fw, eelproto::SetSetting{static_cast<uint8_t>(eelproto::SettingKey::Reversed), 2, 1.0f}, 1);
  send(fw, eelproto::SetSetting{static_cast<uint8_t>(eelproto::SettingKey::AdcCountsPerRad), 3,
                                200.0f},
       2);
  eel_tick(fw, 10000, nullptr, nullptr, nullptr);
  const float phi[EEL_JOINTS] = {0.3f, -0.5f, 0.25f, 1.1f, 0.0f};
  eel_set_joint_angles(fw, phi);
  EelOutputs out;
  eel_tick(fw, 20000, nullptr, nullptr, &out);
  CHECK_EQ(out.measured, 1);
  for (int j = 0; j < EEL_JOINTS; ++j) {
    // Within half an ADC count (1 / 130.4 rad, or 1 / 200 for joint 4).
    CHECK_NEAR(out.phi_measured_rad[j], phi[j], 0.5 / (j == 3 ? 200.0 : 130.4) + 1e-6);
  }
  CHECK_EQ(eel_set_adc(fw, EEL_BATTERY_INPUT, 1023), 0);
  CHECK_EQ(eel_set_adc(fw, EEL_BATTERY_INPUT + 1, 0), -1);
  CHECK_EQ(eel_set_adc(fw, 0, 1024), -1);
  eel_destroy(fw);
}

TEST(every_injected_fault_is_counted_once_in_status) {
  // Bad frames of each kind, duplicates, echoes, frames the stuck UART could not take, a reset:
  // Status's counters equal what was injected.
  EelFw* fw = eel_create(0);
  eel_reboot(fw, 0, static_cast<uint8_t>(eelproto::ResetFlags::BrownOut));
  const uint16_t h = eelproto::kSchemaHash;
  const uint8_t start = static_cast<uint8_t>(MsgId::Start);
  uint8_t seq = 0;
  for (int k = 0; k < 3; ++k) {
    const Bytes bad[] = {
        raw_frame(h, start, seq, nullptr, 0, Spoil::Crc16),
        raw_frame(h, start, seq, nullptr, 0, Spoil::Crc32),
        raw_frame(static_cast<uint16_t>(h ^ 1), start, seq, nullptr, 0),
        frame_of(eelproto::Telemetry{}, seq),  // an echo
    };
    for (const Bytes& b : bad) eel_feed(fw, b.data, b.n);
    const Bytes ok = frame_of(eelproto::SetOffset{0.0f}, seq++);
    eel_feed(fw, ok.data, ok.n);
    eel_feed(fw, ok.data, ok.n);  // a radio retry
    eel_tick(fw, 10000u * (k + 1), nullptr, nullptr, nullptr);
  }
  eel_set_uart_tx_stalled(fw, 1);
  for (int k = 0; k < 40; ++k) send(fw, eelproto::Hello{}, seq++);
  eel_tick(fw, 40000, nullptr, nullptr, nullptr);
  eel_set_uart_tx_stalled(fw, 0);
  Inbox inbox;
  eel_tick(fw, 50000, nullptr, nullptr, nullptr);
  inbox.take(fw);
  const int versions_queued = static_cast<int>(CommandLink::TxQueue().space() /
                                               frame_of(eelproto::Version{}, 0).n);
  const EelStatus s = status_of(fw);
  CHECK_EQ(s.bad_crc, 3);
  CHECK_EQ(s.bad_crc32, 3);
  CHECK_EQ(s.bad_schema, 3);
  CHECK_EQ(s.bad_direction, 3);
  CHECK_EQ(s.duplicates, 3);
  CHECK_EQ(s.frames_bad, 12);
  CHECK_EQ(s.resets, 1);
  CHECK_EQ(s.reset_flags, static_cast<uint8_t>(eelproto::ResetFlags::BrownOut));
  // Replies may fill the whole queue: every Hello beyond what it holds lost its Version, and
  // nothing else was dropped (a Telemetry that finds no room waits).
  CHECK(versions_queued > 0);
  CHECK_EQ(s.tx_dropped, 40 - versions_queued);
  send(fw, eelproto::GetStatus{}, seq++);
  eel_tick(fw, 60000, nullptr, nullptr, nullptr);
  inbox.take(fw);
  CHECK_EQ(inbox.last_status.tx_dropped, s.tx_dropped);
  CHECK_EQ(inbox.last_status.duplicates, 3);
  CHECK_EQ(inbox.last_status.bad_direction, 3);
  CHECK_EQ(inbox.last_status.resets, 1);
  eel_destroy(fw);
}

TEST(every_pass_kicks_the_watchdog) {
  EelFw* fw = eel_create(0);
  const uint32_t before = status_of(fw).watchdog_kicks;
  for (uint32_t t = 1; t <= 50; ++t) eel_pass(fw, t * 100);
  CHECK_EQ(status_of(fw).watchdog_kicks - before, 50u);
  eel_destroy(fw);
}
