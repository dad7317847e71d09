// One pass of the robot's main loop, shared by the AVR image and the native library. `Hal` is the
// board layer chosen at build time by the include path (hal/avr or hal/native): no virtual calls,
// no vtables in the AVR's RAM.
#pragma once
#include <stdint.h>

#include "hal.h"
#include "robot.h"

inline void app_tick(Robot& robot, Hal& hal, uint32_t now_us) {
  uint8_t byte;
  while (hal.uart_read(byte)) robot.on_rx_byte(byte, now_us);
  robot.service(now_us);
  if (robot.control_due(now_us)) {
    hal.busy_pin(true);  // on the AVR a scope (or simavr) times the control update on this pin
    robot.control_update(now_us);
    hal.servo_write_us(robot.pulse_us());
    hal.busy_pin(false);
  }
  Robot::TxQueue& tx = robot.tx();
  while (!tx.empty() && hal.uart_can_write()) hal.uart_write(tx.pop());
}
