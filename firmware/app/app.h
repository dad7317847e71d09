// One pass of the robot's main loop, shared by the AVR image and the native library. `Hal` is the
// board layer chosen at build time by the include path (hal/avr or hal/native): no virtual calls,
// no vtables in the AVR's RAM.
//
// Every pass on the robot does a bounded amount of work (docs/firmware.md, "Main loop"): at most
// kRobotPass.rx_bytes received bytes decoded (their commands only set parameters), at most one
// control update, at most one EEPROM byte of a save started, at most kRobotPass.tx_bytes bytes
// handed to the UART. So a flood of frames
// cannot hold a control update up by more than one short pass. The native build's lockstep tick
// stands for all the passes up to its time (kLockstepTick): every byte received by then is decoded
// before its control update, as the robot's many passes between two updates would have.
#pragma once
#include <stdint.h>

#include "hal.h"
#include "robot.h"
#include "settings_store.h"

struct PassBudget {
  uint16_t rx_bytes;  // received bytes decoded in one pass, at most
  uint16_t tx_bytes;  // bytes handed to the UART in one pass, at most
  bool update_first;  // a due control update before the received bytes (else after them)
  uint8_t eeprom_bytes;  // EEPROM bytes of a save started in one pass, at most
  uint16_t quiet_us;     // this long before a control update is due, a pass only waits for it
};
// On the robot: enough to keep up with the line rate (5.8 bytes a millisecond at 57600 baud) with
// passes every few hundred microseconds, few enough to bound a pass; and a due update first, so
// that it waits for no command (the bytes wait for it instead, 1-2 ms).
// The quiet time before each update: a pass that handles a frame takes up to ~0.6 ms with its
// reply (measured in simavr under a flood of queries, docs/firmware.md), so one starting just
// before the deadline would make the update that late; in the last 0.8 ms the passes leave the
// received bytes in the UART's 64-byte buffer (~5 at the line rate) and the EEPROM alone.
constexpr PassBudget kRobotPass{4, 8, true, 1, 800};
// In lockstep the tick stands for the passes up to its time: the bytes fed before it were read by
// earlier passes, before the update. The native EEPROM programs a byte at once, so a save ends
// within the tick (its time on the robot, ~3.4 ms a byte, is measured in simavr).
constexpr PassBudget kLockstepTick{0xFFFF, 0xFFFF, false, 0xFF, 0};

// Not inlined: app_tick calls it from two places, and one copy saves flash.
__attribute__((noinline)) inline void decode_received(Robot& robot, Hal& hal, uint32_t now_us,
                                                      uint16_t max_bytes) {
  uint8_t byte;
  for (uint16_t k = 0; k < max_bytes && hal.uart_read(byte); ++k) robot.on_rx_byte(byte, now_us);
}

inline void app_tick(Robot& robot, Hal& hal, uint32_t now_us, PassBudget budget = kRobotPass) {
  const bool due = robot.control_due(now_us);
  const bool quiet = !due && budget.quiet_us != 0 && robot.control_due(now_us + budget.quiet_us);
  // Bytes before the update: in lockstep, or in a pass with no update due that is not quiet.
  if (due ? !budget.update_first : !quiet) decode_received(robot, hal, now_us, budget.rx_bytes);
  if (due) {
    hal.busy_pin(true);  // on the AVR a scope (or simavr) times the control update on this pin
    const bool sample = robot.wants_adc();
    if (sample) hal.adc_start();  // the conversions run while the gait is computed
    robot.control_update(now_us);
    robot.joint_update(sample ? hal.adc_wait() : nullptr);
    hal.servo_write_us(robot.pulse_us());
    hal.busy_pin(false);
    robot.service(now_us);
    if (budget.update_first) decode_received(robot, hal, now_us, budget.rx_bytes);
  }
  // A save in progress: on the robot one EEPROM byte started a pass, never waited for (~3.4 ms
  // each, so the control updates go on).
  for (uint8_t k = 0; k < (quiet ? 0 : budget.eeprom_bytes); ++k) {
    const SettingsWriter::Step saved = robot.settings_writer().step(hal);
    if (saved == SettingsWriter::Step::Idle) break;
    if (saved != SettingsWriter::Step::Writing) {
      robot.save_done(saved == SettingsWriter::Step::Written);
      break;
    }
  }
  Robot::TxQueue& tx = robot.tx();
  for (uint16_t k = 0; k < budget.tx_bytes && !tx.empty() && hal.uart_can_write(); ++k) {
    hal.uart_write(tx.pop());
  }
  hal.kick_watchdog();
}
