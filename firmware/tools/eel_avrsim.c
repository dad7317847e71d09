/* eel_avrsim: run the real AVR image of the robot in simavr and observe it like a bench would.
 *
 *   - feeds UART0 bytes at given times (--uart-in FILE, lines "<t_us> <hex bytes...>"),
 *   - logs every byte the firmware sends (--uart-out FILE, lines "<t_us> <hex byte>"),
 *   - times the high pulses on pins (--pulse-pins D2,D3,..., --pulses FILE, lines
 *     "<rise_us> <pin> <width_us>"),
 *   - times a busy pin (--busy-pin D7: high while one control update runs) and reports the cycles,
 *     failing (exit 1) when the longest exceeds --budget-us,
 *   - sets analog inputs at given times (--adc FILE, lines "<t_us> <input 0..7> <millivolts>"; the
 *     reference AVCC is 5000 mV),
 *   - loads and saves the EEPROM (--eeprom-in FILE, --eeprom-out FILE: raw bytes, 1024),
 *   - resets the AVR through its reset pin at given times (--reset-at-us T[,T...]: MCUSR EXTRF),
 *   - does to MCUSR at each reset what a bootloader does (--bootloader old: cleared, as the old
 *     Nano bootloader; optiboot: cleared, its value left in r2; none by default: as ISP-flashed),
 *   - makes the main loop hang at a time (--hang-at-us T: the program counter is sent to an endless
 *     loop, interrupts still on, as a firmware bug would), to see the watchdog reset it,
 *   - paints the RAM between the static data and the top with a pattern before the AVR starts and
 *     reports how deep the stack reached (--stack-paint-from ADDR: the ELF's _end),
 *   - reports the control period (rise to rise of the busy pin), failing (exit 1) when one falls
 *     outside 10 ms +- --period-tolerance-us.
 *
 * Two corrections to simavr 1.6 make the emulated board behave as the real one (docs/firmware.md,
 * "Measured figures"):
 *   - simavr's UART takes 11 bit times a byte for 8N1 (it counts a parity bit), so it could feed
 *     the robot only 90 % of the line rate; the harness sets the receiver's byte time to the true
 *     10 bits at 57600 baud (--line-bytes-per-s 5760), the rate at which the XBee delivers bytes;
 *   - simavr programs an EEPROM byte at once; the harness keeps EECR's EEPE bit set for the real
 *     programming time (--eeprom-write-us 3400, the datasheet's 3.3-3.4 ms), so a firmware that
 *     waits for the EEPROM waits as long as on the chip.
 *
 * Times are simulated microseconds from reset at --freq (16 MHz). Used by `make bench` and by the
 * tests.
 *
 * Built with -DEEL_AVRSIM_LIBRARY -shared (build/tools/libeelavrsim.so) the same code is a library
 * for the processor-in-the-loop driver (host/eelhost/xil/simavr.py, through ctypes): the caller queues
 * UART bytes at times, runs the AVR up to a time, and takes what it sent and the pulses it made
 * (the eas_* functions below).
 */
#include <inttypes.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <avr_adc.h>
#include <avr_eeprom.h>
#include <avr_ioport.h>
#include <avr_uart.h>
#include <sim_avr.h>
#include <sim_elf.h>

#include "timing_gen.h" /* EEL_BAUD, EEL_CONTROL_PERIOD_US: protocol/eelbot.toml */

/* Bytes a second on the line: 8N1 takes 10 bit times a byte (5760 at 57600 baud). */
#define LINE_BYTES_PER_S (EEL_BAUD / 10.0)

#define MAX_PINS 8

struct EasSim;

typedef struct {
  struct EasSim* sim;
  char port;
  int bit;
  int index;
  avr_cycle_count_t rise;
  int high;
} pin_t;

typedef struct {
  avr_cycle_count_t at;
  uint8_t byte;
} timed_byte_t;

typedef struct {
  double rise_us, width_us;
  int pin;
} pulse_t;

typedef struct {
  avr_cycle_count_t at;
  int input;         /* analog input 0..7 */
  uint32_t millivolts;
} adc_event_t;

#define MAX_RESETS 16
#define EECR_ADDR 0x3F  /* data address of EECR */
#define EECR_EEPE 0x02
#define RAMEND_ADDR 0x8FF
#define STACK_PAINT 0xA5
#define BATTERY_INPUT 6          /* A6: firmware/hal/avr/pins.h */
#define BATTERY_DEFAULT_MV 2312  /* 7.4 V (charged 2S) behind the default 3.2 divider */
#define MCUSR_ADDR 0x54 /* data address of MCUSR on the ATmega328P */
#define MCUSR_EXTRF 0x02
/* Last word of the 32 KB flash, beyond any image: where a hang is sent (an "rjmp ." there). */
#define HANG_ADDR 0x7FFE

/* One emulated AVR with its observers. Outputs go to files (command line) or to buffers that the
 * library caller drains (eas_take_*). */
typedef struct EasSim {
  avr_t* avr;
  double cycles_per_us;
  avr_irq_t* uart_input;
  int xon;
  int state;
  pin_t pins[MAX_PINS];
  int npins;
  FILE* uart_out;
  FILE* pulses_out;
  uint64_t pulses_n, uart_out_n;
  /* busy pin statistics (command line) */
  pin_t busy;
  int have_busy;
  uint64_t busy_n, busy_sum, busy_min, busy_max;
  /* control period: rise to rise of the busy pin */
  avr_cycle_count_t last_rise;
  uint64_t period_n, period_min, period_max, period_outside;
  double period_tolerance_us;
  /* UART receiver's byte time (cycles; 0: simavr's own) */
  avr_cycle_count_t uart_cycles_per_byte;
  avr_uart_t* uart;
  /* EEPROM programming time (cycles) and the end of the byte in progress */
  avr_cycle_count_t eeprom_write_cycles, eeprom_busy_until;
  uint64_t eeprom_writes;
  /* what a bootloader does to MCUSR at each reset: 0 none, 1 clears it (the old Nano bootloader),
   * 2 clears it and leaves its value in r2 (Optiboot 4.6 and later) */
  int bootloader;
  /* stack painting: from this data address to RAMEND (0: off) */
  uint32_t paint_from;
  /* UART input: bytes queued by time, delivered in order when the UART takes them (XON) */
  timed_byte_t* in;
  size_t nin, cap_in, next_in;
  /* analog inputs by time, applied in order */
  adc_event_t* adc;
  size_t nadc, cap_adc, next_adc;
  /* resets through the reset pin, and a hang, by time (cycles; 0 = none) */
  avr_cycle_count_t resets[MAX_RESETS];
  int nresets, next_reset;
  avr_cycle_count_t hang_at;
  int hung;
  uint64_t watchdog_resets;
  /* buffered outputs (library) */
  int buffer_outputs;
  timed_byte_t* out;
  size_t nout, cap_out;
  pulse_t* pulses;
  size_t npulses, cap_pulses;
} EasSim;

// simavr logs to stdout; keep stdout for our report and pass on only errors, to stderr.
static void quiet_logger(avr_t* avr, const int level, const char* format, va_list ap) {
  (void)avr;
  if (level <= LOG_ERROR) vfprintf(stderr, format, ap);
}

static double cycles_to_us(const EasSim* s, avr_cycle_count_t c) {
  return (double)c / s->cycles_per_us;
}

static int grow(void** buf, size_t* cap, size_t n, size_t size) {
  if (n < *cap) return 0;
  size_t ncap = *cap ? 2 * *cap : 1024;
  void* p = realloc(*buf, ncap * size);
  if (!p) return -1;
  *buf = p;
  *cap = ncap;
  return 0;
}

static int parse_pin(const char* s, pin_t* p) {
  if (strlen(s) < 2 || s[0] < 'A' || s[0] > 'L') return -1;
  char* end;
  long bit = strtol(s + 1, &end, 10);
  if (*end != '\0' || bit < 0 || bit > 7) return -1;
  p->port = s[0];
  p->bit = (int)bit;
  return 0;
}

static void on_pulse_pin(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  pin_t* p = (pin_t*)param;
  EasSim* s = p->sim;
  if (value && !p->high) {
    p->rise = s->avr->cycle;
  } else if (!value && p->high) {
    ++s->pulses_n;
    const double rise = cycles_to_us(s, p->rise), width = cycles_to_us(s, s->avr->cycle - p->rise);
    if (s->pulses_out) fprintf(s->pulses_out, "%.3f %c%d %.3f\n", rise, p->port, p->bit, width);
    if (s->buffer_outputs &&
        grow((void**)&s->pulses, &s->cap_pulses, s->npulses, sizeof(pulse_t)) == 0) {
      s->pulses[s->npulses++] = (pulse_t){rise, width, p->index};
    }
  }
  p->high = value != 0;
}

static void on_busy_pin(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  EasSim* s = (EasSim*)param;
  if (value && !s->busy.high) {
    s->busy.rise = s->avr->cycle;
    if (s->last_rise) {
      const uint64_t d = s->avr->cycle - s->last_rise;
      ++s->period_n;
      if (d < s->period_min) s->period_min = d;
      if (d > s->period_max) s->period_max = d;
      if (s->period_tolerance_us > 0 &&
          fabs(cycles_to_us(s, d) - (double)EEL_CONTROL_PERIOD_US) > s->period_tolerance_us) {
        ++s->period_outside;
      }
    }
    s->last_rise = s->avr->cycle;
  } else if (!value && s->busy.high) {
    uint64_t d = s->avr->cycle - s->busy.rise;
    ++s->busy_n;
    s->busy_sum += d;
    if (d < s->busy_min) s->busy_min = d;
    if (d > s->busy_max) s->busy_max = d;
  }
  s->busy.high = value != 0;
}

static void on_uart_out(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  EasSim* s = (EasSim*)param;
  ++s->uart_out_n;
  if (s->uart_out) fprintf(s->uart_out, "%.3f %02x\n", cycles_to_us(s, s->avr->cycle), value & 0xFF);
  if (s->buffer_outputs &&
      grow((void**)&s->out, &s->cap_out, s->nout, sizeof(timed_byte_t)) == 0) {
    s->out[s->nout++] = (timed_byte_t){s->avr->cycle, (uint8_t)(value & 0xFF)};
  }
}

static void on_xon(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  (void)value;
  ((EasSim*)param)->xon = 1;
}

static void on_xoff(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  (void)value;
  ((EasSim*)param)->xon = 0;
}

/* The EEPROM's programming time: a write of EECR that sets EEPE starts it; until it ends, reads
 * of EECR show EEPE set, as on the chip (simavr itself clears it at once). */
static void on_eecr_write(struct avr_t* avr, avr_io_addr_t addr, uint8_t v, void* param) {
  (void)addr;
  EasSim* s = (EasSim*)param;
  if ((v & EECR_EEPE) && s->eeprom_write_cycles) {
    s->eeprom_busy_until = avr->cycle + s->eeprom_write_cycles;
    ++s->eeprom_writes;
  }
}

static uint8_t on_eecr_read(struct avr_t* avr, avr_io_addr_t addr, void* param) {
  EasSim* s = (EasSim*)param;
  uint8_t v = avr->data[addr] & (uint8_t)~EECR_EEPE;
  if (avr->cycle < s->eeprom_busy_until) v |= EECR_EEPE;
  return v;
}

/* The UART receiver module of simavr (its byte time is corrected in apply_due_events). */
static avr_uart_t* find_uart0(avr_t* avr) {
  for (avr_io_t* io = avr->io_port; io; io = io->next) {
    if (io->kind && !strcmp(io->kind, "uart") && ((avr_uart_t*)io)->name == '0') {
      return (avr_uart_t*)io;
    }
  }
  return NULL;
}

/* The reset vector is about to run: do to MCUSR what the bootloader would have. */
static void bootloader_ran(EasSim* s) {
  if (!s->bootloader) return;
  if (s->bootloader == 2) s->avr->data[2] = s->avr->data[MCUSR_ADDR];
  s->avr->data[MCUSR_ADDR] = 0;
}

/* ------------------------------------------------------------------ API (also used by main) */

/* Load the ELF and reset the AVR; NULL (with a message on stderr) when that fails. */
EasSim* eas_create(const char* elf, const char* mcu, unsigned long freq) {
  if (!elf || !mcu || freq == 0) return NULL;
  avr_global_logger_set(quiet_logger);
  elf_firmware_t fw;
  memset(&fw, 0, sizeof fw);
  if (elf_read_firmware(elf, &fw) != 0) {
    fprintf(stderr, "eel_avrsim: cannot read ELF: %s\n", elf);
    return NULL;
  }
  snprintf(fw.mmcu, sizeof fw.mmcu, "%s", mcu);
  fw.frequency = (uint32_t)freq;
  avr_t* avr = avr_make_mcu_by_name(fw.mmcu);
  if (!avr) {
    fprintf(stderr, "eel_avrsim: unknown MCU: %s\n", mcu);
    return NULL;
  }
  EasSim* s = (EasSim*)calloc(1, sizeof(EasSim));
  if (!s) return NULL;
  s->avr = avr;
  s->cycles_per_us = (double)freq / 1e6;
  s->busy_min = UINT64_MAX;
  s->period_min = UINT64_MAX;
  s->state = cpu_Running;
  avr_init(avr);
  avr_load_firmware(avr, &fw);
  avr->log = LOG_ERROR;
  avr->vcc = avr->avcc = avr->aref = 5000;  // the Nano's 5 V: the ADC's AVCC reference
  uint32_t uart_flags = 0;
  avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &uart_flags);
  uart_flags &= ~(uint32_t)AVR_UART_FLAG_STDIO;  // we log the bytes ourselves
  avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &uart_flags);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                          on_uart_out, s);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), on_xon,
                          s);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
                          on_xoff, s);
  s->uart_input = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
  s->uart = find_uart0(avr);
  s->uart_cycles_per_byte = (avr_cycle_count_t)(freq / LINE_BYTES_PER_S);
  s->eeprom_write_cycles = (avr_cycle_count_t)(3400.0 * s->cycles_per_us);
  avr_register_io_write(avr, EECR_ADDR, on_eecr_write, s);
  avr_register_io_read(avr, EECR_ADDR, on_eecr_read, s);
  /* A charged battery behind the default divider, until told otherwise (--adc). */
  avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + BATTERY_INPUT),
                BATTERY_DEFAULT_MV);
  return s;
}

/* Byte time of the UART receiver: line_bytes_per_s (5760 for 8N1 at 57600 baud, the default),
 * or 0 for simavr's own (11 bit times a byte). */
void eas_set_line_rate(EasSim* s, double line_bytes_per_s) {
  s->uart_cycles_per_byte =
      line_bytes_per_s > 0 ? (avr_cycle_count_t)(s->cycles_per_us * 1e6 / line_bytes_per_s) : 0;
}

/* Programming time of an EEPROM byte, us (3400 by default; 0: at once, as simavr). */
void eas_set_eeprom_write_us(EasSim* s, double us) {
  s->eeprom_write_cycles = (avr_cycle_count_t)(us * s->cycles_per_us);
}

/* Fill the RAM from data address `from` (the ELF's _end) to RAMEND with a pattern, before the AVR
 * runs; eas_stack_peak then tells how deep the stack went. */
void eas_paint_stack(EasSim* s, uint32_t from) {
  if (from < 0x100 || from > RAMEND_ADDR) return;
  s->paint_from = from;
  memset(s->avr->data + from, STACK_PAINT, RAMEND_ADDR + 1 - from);
}

/* Bytes of RAM below RAMEND that the stack has written (0 without painting). */
uint32_t eas_stack_peak(const EasSim* s) {
  if (!s->paint_from) return 0;
  uint32_t a = s->paint_from;
  while (a <= RAMEND_ADDR && s->avr->data[a] == STACK_PAINT) ++a;
  return RAMEND_ADDR + 1 - a;
}

/* Emulate a bootloader's effect on the reset cause (0 none, 1 old Nano bootloader, 2 Optiboot),
 * from the power-on on: call before running. */
void eas_set_bootloader(EasSim* s, int mode) {
  s->bootloader = mode;
  bootloader_ran(s);
}

void eas_destroy(EasSim* s) {
  if (!s) return;
  avr_terminate(s->avr);
  free(s->in);
  free(s->adc);
  free(s->out);
  free(s->pulses);
  free(s);
}

/* Keep what the firmware sends and the pulses in buffers for eas_take_* (1) or not (0). */
void eas_buffer_outputs(EasSim* s, int on) { s->buffer_outputs = on != 0; }

/* Time the high pulses on a pin such as "D2"; returns the pin's index, -1 for a bad pin. */
int eas_watch_pin(EasSim* s, const char* name) {
  if (s->npins == MAX_PINS) return -1;
  pin_t* p = &s->pins[s->npins];
  if (parse_pin(name, p) != 0) return -1;
  p->index = s->npins;
  p->sim = s;
  avr_irq_register_notify(avr_io_getirq(s->avr, AVR_IOCTL_IOPORT_GETIRQ(p->port), p->bit),
                          on_pulse_pin, p);
  return s->npins++;
}

/* Time the control updates on a busy pin (statistics only: eas_busy_stats). */
int eas_watch_busy_pin(EasSim* s, const char* name) {
  if (parse_pin(name, &s->busy) != 0) return -1;
  s->have_busy = 1;
  avr_irq_register_notify(avr_io_getirq(s->avr, AVR_IOCTL_IOPORT_GETIRQ(s->busy.port), s->busy.bit),
                          on_busy_pin, s);
  return 0;
}

/* Queue a byte for the UART at t_us (not before earlier ones); it enters the UART's receive FIFO
 * at that time, or later while the FIFO is full. Returns -1 when out of memory. */
int eas_uart_push(EasSim* s, double t_us, uint8_t byte) {
  if (grow((void**)&s->in, &s->cap_in, s->nin, sizeof(timed_byte_t)) != 0) return -1;
  s->in[s->nin].at = (avr_cycle_count_t)(t_us * s->cycles_per_us);
  s->in[s->nin].byte = byte;
  ++s->nin;
  return 0;
}

/* Set analog input `input` (0..7) to `millivolts` at t_us (not before earlier ones). Returns -1
 * for a bad input or when out of memory. */
int eas_adc_push(EasSim* s, double t_us, int input, uint32_t millivolts) {
  if (input < 0 || input > 7) return -1;
  if (grow((void**)&s->adc, &s->cap_adc, s->nadc, sizeof(adc_event_t)) != 0) return -1;
  s->adc[s->nadc++] = (adc_event_t){(avr_cycle_count_t)(t_us * s->cycles_per_us), input,
                                    millivolts};
  return 0;
}

/* Reset through the reset pin at t_us (MCUSR shows EXTRF, RAM and EEPROM are kept). */
int eas_reset_at(EasSim* s, double t_us) {
  if (s->nresets == MAX_RESETS) return -1;
  s->resets[s->nresets++] = (avr_cycle_count_t)(t_us * s->cycles_per_us);
  return 0;
}

/* Make the main loop hang at t_us: the first instruction after it with interrupts enabled (so not
 * inside an interrupt) jumps to an endless loop. Interrupts go on; only a reset ends it. */
void eas_hang_at(EasSim* s, double t_us) { s->hang_at = (avr_cycle_count_t)(t_us * s->cycles_per_us); }

/* Copy the first n bytes of the EEPROM (at most 1024) from (to_avr 0) or to (to_avr 1) buf.
 * Returns 0, or -1 for a bad size. (simavr's EEPROM ioctl reports -1 whether or not it worked.) */
int eas_eeprom(EasSim* s, uint8_t* buf, uint32_t n, int to_avr) {
  if (n == 0 || n > 1024) return -1;
  avr_eeprom_desc_t d = {buf, 0, n};
  avr_ioctl(s->avr, to_avr ? AVR_IOCTL_EEPROM_SET : AVR_IOCTL_EEPROM_GET, &d);
  return 0;
}

static void apply_due_events(EasSim* s) {
  avr_t* avr = s->avr;
  /* simavr recomputes the byte time whenever the firmware sets the baud rate: correct it. */
  if (s->uart && s->uart_cycles_per_byte) s->uart->cycles_per_byte = s->uart_cycles_per_byte;
  while (s->xon && s->next_in < s->nin && s->in[s->next_in].at <= avr->cycle) {
    avr_raise_irq(s->uart_input, s->in[s->next_in++].byte);
  }
  while (s->next_adc < s->nadc && s->adc[s->next_adc].at <= avr->cycle) {
    const adc_event_t* e = &s->adc[s->next_adc++];
    avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + e->input), e->millivolts);
  }
  if (s->next_reset < s->nresets && s->resets[s->next_reset] <= avr->cycle) {
    ++s->next_reset;
    s->hung = 0;
    avr_reset(avr);
    avr->data[MCUSR_ADDR] = MCUSR_EXTRF;
    bootloader_ran(s);
  }
  if (s->hang_at && s->hang_at <= avr->cycle && avr->sreg[S_I]) {
    avr->flash[HANG_ADDR] = 0xFF;  // rjmp . (0xCFFF), little-endian
    avr->flash[HANG_ADDR + 1] = 0xCF;
    avr->pc = HANG_ADDR;
    s->hung = 1;
    s->hang_at = 0;  // once: the reset ends it
  }
}

/* Run until the simulated time reaches t_us. Returns 0, or 1 when the AVR crashed or stopped. */
int eas_run_until(EasSim* s, double t_us) {
  const avr_cycle_count_t end = (avr_cycle_count_t)(t_us * s->cycles_per_us);
  while (s->avr->cycle < end && s->state != cpu_Done && s->state != cpu_Crashed) {
    apply_due_events(s);
    const avr_flashaddr_t pc = s->avr->pc;
    s->state = avr_run(s->avr);
    // The watchdog's reset sends the program counter to 0 from wherever it was.
    if (s->avr->pc == 0 && pc != 0 && (s->avr->data[MCUSR_ADDR] & 0x08)) {
      ++s->watchdog_resets;
      s->hung = 0;
      bootloader_ran(s);
    }
  }
  return s->state == cpu_Done || s->state == cpu_Crashed;
}

double eas_now_us(const EasSim* s) { return cycles_to_us(s, s->avr->cycle); }

/* Bytes the firmware sent since the last call (up to cap), with their times. */
size_t eas_take_uart(EasSim* s, double* t_us, uint8_t* bytes, size_t cap) {
  size_t n = s->nout < cap ? s->nout : cap;
  for (size_t i = 0; i < n; ++i) {
    t_us[i] = cycles_to_us(s, s->out[i].at);
    bytes[i] = s->out[i].byte;
  }
  memmove(s->out, s->out + n, (s->nout - n) * sizeof(timed_byte_t));
  s->nout -= n;
  return n;
}

/* Pulses completed since the last call (up to cap): rise time, width, index of the pin. */
size_t eas_take_pulses(EasSim* s, double* rise_us, double* width_us, int32_t* pin, size_t cap) {
  size_t n = s->npulses < cap ? s->npulses : cap;
  for (size_t i = 0; i < n; ++i) {
    rise_us[i] = s->pulses[i].rise_us;
    width_us[i] = s->pulses[i].width_us;
    pin[i] = s->pulses[i].pin;
  }
  memmove(s->pulses, s->pulses + n, (s->npulses - n) * sizeof(pulse_t));
  s->npulses -= n;
  return n;
}

/* Watchdog resets so far. */
uint64_t eas_watchdog_resets(const EasSim* s) { return s->watchdog_resets; }

/* UART input bytes delivered to the AVR so far. */
size_t eas_uart_delivered(const EasSim* s) { return s->next_in; }

/* ------------------------------------------------------------------ command line */
#ifndef EEL_AVRSIM_LIBRARY

static void die(const char* msg, const char* arg) {
  fprintf(stderr, "eel_avrsim: %s%s%s\n", msg, arg ? ": " : "", arg ? arg : "");
  exit(2);
}

static void read_uart_input(EasSim* sim, const char* path) {
  FILE* f = fopen(path, "r");
  if (!f) die("cannot open --uart-in", path);
  char line[8192];
  int lineno = 0;
  while (fgets(line, sizeof line, f)) {
    ++lineno;
    char* s = line;
    while (*s == ' ' || *s == '\t') ++s;
    if (*s == '#' || *s == '\n' || *s == '\0') continue;
    char* end;
    double t_us = strtod(s, &end);
    if (end == s || t_us < 0) {
      fprintf(stderr, "eel_avrsim: %s:%d: expected '<t_us> <hex bytes>'\n", path, lineno);
      exit(2);
    }
    s = end;
    for (;;) {
      while (*s == ' ' || *s == '\t') ++s;
      if (*s == '\n' || *s == '\0') break;
      unsigned v;
      int used;
      if (sscanf(s, "%2x%n", &v, &used) != 1) {
        fprintf(stderr, "eel_avrsim: %s:%d: bad hex byte\n", path, lineno);
        exit(2);
      }
      if (eas_uart_push(sim, t_us, (uint8_t)v) != 0) die("out of memory reading", path);
      s += used;
    }
  }
  fclose(f);
}

static void read_adc_input(EasSim* sim, const char* path) {
  FILE* f = fopen(path, "r");
  if (!f) die("cannot open --adc", path);
  char line[256];
  int lineno = 0;
  while (fgets(line, sizeof line, f)) {
    ++lineno;
    double t_us;
    int input;
    unsigned mv;
    if (line[0] == '#' || line[0] == '\n') continue;
    if (sscanf(line, "%lf %d %u", &t_us, &input, &mv) != 3 || t_us < 0 ||
        eas_adc_push(sim, t_us, input, mv) != 0) {
      fprintf(stderr, "eel_avrsim: %s:%d: expected '<t_us> <input 0..7> <millivolts>'\n", path,
              lineno);
      exit(2);
    }
  }
  fclose(f);
}

static void eeprom_file(EasSim* sim, const char* path, int load) {
  uint8_t buf[1024];
  memset(buf, 0xFF, sizeof buf);
  FILE* f = fopen(path, load ? "rb" : "wb");
  if (!f) die(load ? "cannot open --eeprom-in" : "cannot write --eeprom-out", path);
  if (load) {
    const size_t n = fread(buf, 1, sizeof buf, f);
    if (n == 0 || eas_eeprom(sim, buf, (uint32_t)n, 1) != 0) die("cannot load EEPROM from", path);
  } else if (eas_eeprom(sim, buf, sizeof buf, 0) != 0 || fwrite(buf, 1, sizeof buf, f) != sizeof buf) {
    die("cannot save EEPROM to", path);
  }
  fclose(f);
}

static void usage(void) {
  fprintf(stderr,
          "usage: eel_avrsim --elf FILE [--mcu atmega328p] [--freq 16000000] [--run-ms 1000]\n"
          "       [--uart-in FILE] [--uart-out FILE] [--pulse-pins D2,D3,...] [--pulses FILE]\n"
          "       [--busy-pin D7] [--budget-us N] [--adc FILE] [--eeprom-in FILE]\n"
          "       [--eeprom-out FILE] [--reset-at-us T[,T...]] [--hang-at-us T]\n"
          "       [--line-bytes-per-s 5760] [--eeprom-write-us 3400] [--stack-paint-from ADDR]\n"
          "       [--period-tolerance-us 300] [--bootloader none|old|optiboot]\n");
  exit(2);
}

int main(int argc, char** argv) {
  const char *elf = NULL, *mcu = "atmega328p", *uart_in = NULL, *uart_out = NULL;
  const char *pulses = NULL, *pulse_pins = NULL, *busy = NULL, *adc = NULL;
  const char *eeprom_in = NULL, *eeprom_out = NULL, *reset_at = NULL;
  double hang_at_us = 0.0, line_rate = LINE_BYTES_PER_S, eeprom_write_us = 3400.0;
  double tolerance_us = 0.0;
  unsigned long paint_from = 0;
  int bootloader = 0;
  unsigned long freq = 16000000UL;
  double run_ms = 1000.0, budget_us = 0.0;
  for (int i = 1; i < argc; ++i) {
    const char* a = argv[i];
    if (i + 1 >= argc) usage();
    const char* v = argv[++i];
    if (!strcmp(a, "--elf")) elf = v;
    else if (!strcmp(a, "--mcu")) mcu = v;
    else if (!strcmp(a, "--freq")) freq = strtoul(v, NULL, 10);
    else if (!strcmp(a, "--run-ms")) run_ms = strtod(v, NULL);
    else if (!strcmp(a, "--uart-in")) uart_in = v;
    else if (!strcmp(a, "--uart-out")) uart_out = v;
    else if (!strcmp(a, "--pulses")) pulses = v;
    else if (!strcmp(a, "--pulse-pins")) pulse_pins = v;
    else if (!strcmp(a, "--busy-pin")) busy = v;
    else if (!strcmp(a, "--budget-us")) budget_us = strtod(v, NULL);
    else if (!strcmp(a, "--adc")) adc = v;
    else if (!strcmp(a, "--eeprom-in")) eeprom_in = v;
    else if (!strcmp(a, "--eeprom-out")) eeprom_out = v;
    else if (!strcmp(a, "--reset-at-us")) reset_at = v;
    else if (!strcmp(a, "--hang-at-us")) hang_at_us = strtod(v, NULL);
    else if (!strcmp(a, "--line-bytes-per-s")) line_rate = strtod(v, NULL);
    else if (!strcmp(a, "--eeprom-write-us")) eeprom_write_us = strtod(v, NULL);
    else if (!strcmp(a, "--stack-paint-from")) paint_from = strtoul(v, NULL, 0);
    else if (!strcmp(a, "--period-tolerance-us")) tolerance_us = strtod(v, NULL);
    else if (!strcmp(a, "--bootloader")) {
      if (!strcmp(v, "none")) bootloader = 0;
      else if (!strcmp(v, "old")) bootloader = 1;
      else if (!strcmp(v, "optiboot")) bootloader = 2;
      else usage();
    }
    else usage();
  }
  if (!elf || freq == 0 || run_ms <= 0) usage();

  EasSim* sim = eas_create(elf, mcu, freq);
  if (!sim) exit(2);
  eas_set_line_rate(sim, line_rate);
  eas_set_eeprom_write_us(sim, eeprom_write_us);
  sim->period_tolerance_us = tolerance_us;
  eas_set_bootloader(sim, bootloader);
  if (paint_from) eas_paint_stack(sim, (uint32_t)paint_from);
  if (uart_in) read_uart_input(sim, uart_in);
  if (adc) read_adc_input(sim, adc);
  if (eeprom_in) eeprom_file(sim, eeprom_in, 1);
  if (hang_at_us > 0) eas_hang_at(sim, hang_at_us);
  if (reset_at) {
    char buf[256];
    snprintf(buf, sizeof buf, "%s", reset_at);
    for (char* tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
      if (eas_reset_at(sim, strtod(tok, NULL)) != 0) die("too many resets", tok);
    }
  }
  if (uart_out) {
    sim->uart_out = !strcmp(uart_out, "-") ? stdout : fopen(uart_out, "w");
    if (!sim->uart_out) die("cannot write --uart-out", uart_out);
  }
  if (pulses) {
    sim->pulses_out = fopen(pulses, "w");
    if (!sim->pulses_out) die("cannot write --pulses", pulses);
  }
  if (pulse_pins) {
    char buf[256];
    snprintf(buf, sizeof buf, "%s", pulse_pins);
    for (char* tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
      if (eas_watch_pin(sim, tok) < 0) die("bad pin", tok);
    }
  }
  if (busy && eas_watch_busy_pin(sim, busy) != 0) die("bad pin", busy);

  const clock_t cpu0 = clock();
  eas_run_until(sim, run_ms * 1000.0);
  const double cpu_s = (double)(clock() - cpu0) / CLOCKS_PER_SEC;

  printf("elf: %s (%s at %lu Hz)\n", elf, mcu, freq);
  printf("simulated: %.1f ms (%" PRIu64 " cycles) in %.2f s of host CPU\n",
         eas_now_us(sim) / 1000.0, (uint64_t)sim->avr->cycle, cpu_s);
  printf("uart: %zu of %zu input bytes delivered, %" PRIu64 " output bytes\n", sim->next_in,
         sim->nin, sim->uart_out_n);
  if (sim->npins) printf("pulses: %" PRIu64 " on %d pins\n", sim->pulses_n, sim->npins);
  printf("watchdog resets: %" PRIu64 "\n", sim->watchdog_resets);
  printf("eeprom writes: %" PRIu64 " bytes\n", sim->eeprom_writes);
  if (sim->paint_from) {
    printf("stack peak: %" PRIu32 " bytes (painted from 0x%04" PRIx32 " to RAMEND 0x%04x)\n",
           eas_stack_peak(sim), sim->paint_from, RAMEND_ADDR);
  }
  if (eeprom_out) eeprom_file(sim, eeprom_out, 0);
  int status = 0;
  if (sim->state == cpu_Crashed) {
    printf("FAIL: the AVR crashed\n");
    status = 1;
  }
  if (sim->have_busy) {
    if (sim->busy_n == 0) {
      printf("FAIL: no high pulse on busy pin %c%d\n", sim->busy.port, sim->busy.bit);
      status = 1;
    } else {
      const double mean = (double)sim->busy_sum / (double)sim->busy_n;
      printf("control update (busy pin %c%d high): n=%" PRIu64 " cycles min=%" PRIu64
             " mean=%.0f max=%" PRIu64 "\n",
             sim->busy.port, sim->busy.bit, sim->busy_n, sim->busy_min, mean, sim->busy_max);
      printf("control update time: min=%.1f us mean=%.1f us max=%.1f us at %.0f MHz\n",
             cycles_to_us(sim, sim->busy_min), mean / sim->cycles_per_us,
             cycles_to_us(sim, sim->busy_max), sim->cycles_per_us);
      if (sim->period_n) {
        printf("control period: n=%" PRIu64 " min=%.1f us max=%.1f us, %" PRIu64
               " outside %lu +- %.0f us\n",
               sim->period_n, cycles_to_us(sim, sim->period_min),
               cycles_to_us(sim, sim->period_max), sim->period_outside, EEL_CONTROL_PERIOD_US,
               sim->period_tolerance_us);
      }
      if (budget_us > 0) {
        const int ok = cycles_to_us(sim, sim->busy_max) <= budget_us;
        printf("budget: %.0f us: %s\n", budget_us, ok ? "OK" : "FAIL (over budget)");
        if (!ok) status = 1;
      }
      if (sim->period_tolerance_us > 0) {
        const int ok = sim->period_outside == 0;
        printf("period: %lu +- %.0f us: %s\n", EEL_CONTROL_PERIOD_US, sim->period_tolerance_us,
               ok ? "OK" : "FAIL (periods outside)");
        if (!ok) status = 1;
      }
    }
  }
  if (sim->uart_out && sim->uart_out != stdout) fclose(sim->uart_out);
  if (sim->pulses_out) fclose(sim->pulses_out);
  eas_destroy(sim);
  return status;
}
#endif  // EEL_AVRSIM_LIBRARY
