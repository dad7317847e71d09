/* C API of the native firmware library (build/libeelfw.so), for Python (host/eelhost/
 * native_firmware.py, cffi ABI mode) and any C caller. The caller owns time: every call that needs
 * it takes now_us, a 32-bit microsecond clock that wraps like the AVR's micros().
 * Arrays hold one value per joint, joint 1 (tail) first: EEL_JOINTS of them. */
#ifndef EEL_NATIVE_H
#define EEL_NATIVE_H
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define EEL_ABI_VERSION 1
#define EEL_JOINTS 5

typedef struct EelFw EelFw;

typedef struct EelOutputs {
  float alpha_rad[EEL_JOINTS];       /* joint references, clamped to the joint limit */
  float alpha_dot_rad_s[EEL_JOINTS]; /* their rates (0 where clamped) */
  float torque_nm[EEL_JOINTS];       /* PD torques for the phi passed in, clamped */
  uint16_t pulse_us[EEL_JOINTS];     /* servo pulse widths the AVR would output */
  uint8_t control_ran;               /* 1 when this tick ran a control update */
} EelOutputs;

typedef struct EelStatus {
  uint8_t state; /* eelproto::State: 0 IDLE, 1 RUNNING, 2 FAILSAFE */
  float amplitude_rad, beta_rad, offset_rad, phase_rad;
  float target_amplitude_rad, target_omega_rad_s, target_beta_rad, target_offset_rad;
  float kp_nm_per_rad, kd_nms_per_rad, torque_limit_nm;
  uint32_t last_valid_rx_us;
  uint16_t frames_ok, bad_cobs, bad_short, bad_oversize, bad_crc, bad_schema, bad_unknown_id,
      bad_length, duplicates, lost, tx_dropped, frames_bad;
} EelStatus;

uint32_t eel_abi_version(void);
uint16_t eel_schema_hash(void);
/* A firmware instance in its boot state at now_us; NULL when out of memory. */
EelFw* eel_create(uint32_t now_us);
void eel_destroy(EelFw* fw);
/* Back to the boot state (as after a power cycle): queues emptied, control period 10000 us. */
void eel_reset(EelFw* fw, uint32_t now_us);
/* 0 = a control update on every tick (lockstep with a plant); default 10000 as on the AVR. */
void eel_set_control_period_us(EelFw* fw, uint32_t period_us);
/* Bytes "received by the UART"; returns how many fit in the receive queue. */
size_t eel_feed(EelFw* fw, const uint8_t* data, size_t n);
/* Move up to cap "transmitted" bytes into out; returns how many. */
size_t eel_take(EelFw* fw, uint8_t* out, size_t cap);
/* One pass of the main loop at now_us with the plant's joint angles and rates (either may be NULL:
 * zeros). Fills out (may be NULL). */
void eel_tick(EelFw* fw, uint32_t now_us, const float* phi_rad, const float* phi_dot_rad_s,
              EelOutputs* out);
void eel_status(const EelFw* fw, EelStatus* out);

#ifdef __cplusplus
}
#endif
#endif
