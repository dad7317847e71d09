/* eel_avrsim: run the real AVR image of the robot in simavr and observe it like a bench would.
 *
 *   - feeds UART0 bytes at given times (--uart-in FILE, lines "<t_us> <hex bytes...>"),
 *   - logs every byte the firmware sends (--uart-out FILE, lines "<t_us> <hex byte>"),
 *   - times the high pulses on pins (--pulse-pins D2,D3,..., --pulses FILE, lines
 *     "<rise_us> <pin> <width_us>"),
 *   - times a busy pin (--busy-pin D7: high while one control update runs) and reports the cycles,
 *     failing (exit 1) when the longest exceeds --budget-us.
 *
 * Times are simulated microseconds from reset at --freq (16 MHz). Used by `make bench` and by the
 * tests; a later processor-in-the-loop rig can drive the same options from a plant simulation.
 */
#include <inttypes.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <avr_ioport.h>
#include <avr_uart.h>
#include <sim_avr.h>
#include <sim_elf.h>

#define MAX_PINS 8
#define MAX_INPUT (1 << 16)

typedef struct {
  char port;
  int bit;
  avr_cycle_count_t rise;
  int high;
} pin_t;

static avr_t* g_avr;
static double g_cycles_per_us;
static FILE* g_uart_out;
static FILE* g_pulses_out;
static pin_t g_pins[MAX_PINS];
static int g_npins;
static pin_t g_busy;
static int g_have_busy;
static uint64_t g_busy_n, g_busy_sum, g_busy_min = UINT64_MAX, g_busy_max;
static uint64_t g_pulses_n, g_uart_out_n;
static int g_xon;

static struct {
  avr_cycle_count_t at;
  uint8_t byte;
} g_input[MAX_INPUT];
static size_t g_ninput, g_next_input;

// simavr logs to stdout; keep stdout for our report and pass on only errors, to stderr.
static void quiet_logger(avr_t* avr, const int level, const char* format, va_list ap) {
  (void)avr;
  if (level <= LOG_ERROR) vfprintf(stderr, format, ap);
}

static void die(const char* msg, const char* arg) {
  fprintf(stderr, "eel_avrsim: %s%s%s\n", msg, arg ? ": " : "", arg ? arg : "");
  exit(2);
}

static double cycles_to_us(avr_cycle_count_t c) { return (double)c / g_cycles_per_us; }

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
  if (value && !p->high) {
    p->rise = g_avr->cycle;
  } else if (!value && p->high) {
    ++g_pulses_n;
    if (g_pulses_out) {
      fprintf(g_pulses_out, "%.3f %c%d %.3f\n", cycles_to_us(p->rise), p->port, p->bit,
              cycles_to_us(g_avr->cycle - p->rise));
    }
  }
  p->high = value != 0;
}

static void on_busy_pin(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  (void)param;
  if (value && !g_busy.high) {
    g_busy.rise = g_avr->cycle;
  } else if (!value && g_busy.high) {
    uint64_t d = g_avr->cycle - g_busy.rise;
    ++g_busy_n;
    g_busy_sum += d;
    if (d < g_busy_min) g_busy_min = d;
    if (d > g_busy_max) g_busy_max = d;
  }
  g_busy.high = value != 0;
}

static void on_uart_out(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  (void)param;
  ++g_uart_out_n;
  if (g_uart_out) fprintf(g_uart_out, "%.3f %02x\n", cycles_to_us(g_avr->cycle), value & 0xFF);
}

static void on_xon(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  (void)value;
  (void)param;
  g_xon = 1;
}

static void on_xoff(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  (void)value;
  (void)param;
  g_xon = 0;
}

static void read_uart_input(const char* path) {
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
      if (g_ninput == MAX_INPUT) die("too many input bytes", path);
      g_input[g_ninput].at = (avr_cycle_count_t)(t_us * g_cycles_per_us);
      g_input[g_ninput].byte = (uint8_t)v;
      ++g_ninput;
      s += used;
    }
  }
  fclose(f);
}

static void usage(void) {
  fprintf(stderr,
          "usage: eel_avrsim --elf FILE [--mcu atmega328p] [--freq 16000000] [--run-ms 1000]\n"
          "       [--uart-in FILE] [--uart-out FILE] [--pulse-pins D2,D3,...] [--pulses FILE]\n"
          "       [--busy-pin D7] [--budget-us N]\n");
  exit(2);
}

int main(int argc, char** argv) {
  const char *elf = NULL, *mcu = "atmega328p", *uart_in = NULL, *uart_out = NULL;
  const char *pulses = NULL, *pulse_pins = NULL, *busy = NULL;
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
    else usage();
  }
  if (!elf || freq == 0 || run_ms <= 0) usage();
  g_cycles_per_us = (double)freq / 1e6;

  avr_global_logger_set(quiet_logger);
  elf_firmware_t fw;
  memset(&fw, 0, sizeof fw);
  if (elf_read_firmware(elf, &fw) != 0) die("cannot read ELF", elf);
  snprintf(fw.mmcu, sizeof fw.mmcu, "%s", mcu);
  fw.frequency = (uint32_t)freq;
  g_avr = avr_make_mcu_by_name(fw.mmcu);
  if (!g_avr) die("unknown MCU", mcu);
  avr_init(g_avr);
  avr_load_firmware(g_avr, &fw);
  g_avr->log = LOG_ERROR;
  uint32_t uart_flags = 0;
  avr_ioctl(g_avr, AVR_IOCTL_UART_GET_FLAGS('0'), &uart_flags);
  uart_flags &= ~(uint32_t)AVR_UART_FLAG_STDIO;  // we log the bytes ourselves
  avr_ioctl(g_avr, AVR_IOCTL_UART_SET_FLAGS('0'), &uart_flags);

  if (uart_in) read_uart_input(uart_in);
  if (uart_out) {
    g_uart_out = !strcmp(uart_out, "-") ? stdout : fopen(uart_out, "w");
    if (!g_uart_out) die("cannot write --uart-out", uart_out);
  }
  if (pulses) {
    g_pulses_out = fopen(pulses, "w");
    if (!g_pulses_out) die("cannot write --pulses", pulses);
  }
  avr_irq_register_notify(avr_io_getirq(g_avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                          on_uart_out, NULL);
  avr_irq_register_notify(avr_io_getirq(g_avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
                          on_xon, NULL);
  avr_irq_register_notify(avr_io_getirq(g_avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
                          on_xoff, NULL);
  avr_irq_t* uart_input = avr_io_getirq(g_avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
  if (pulse_pins) {
    char buf[256];
    snprintf(buf, sizeof buf, "%s", pulse_pins);
    for (char* tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
      if (g_npins == MAX_PINS || parse_pin(tok, &g_pins[g_npins]) != 0) die("bad pin", tok);
      avr_irq_register_notify(
          avr_io_getirq(g_avr, AVR_IOCTL_IOPORT_GETIRQ(g_pins[g_npins].port), g_pins[g_npins].bit),
          on_pulse_pin, &g_pins[g_npins]);
      ++g_npins;
    }
  }
  if (busy) {
    if (parse_pin(busy, &g_busy) != 0) die("bad pin", busy);
    g_have_busy = 1;
    avr_irq_register_notify(avr_io_getirq(g_avr, AVR_IOCTL_IOPORT_GETIRQ(g_busy.port), g_busy.bit),
                            on_busy_pin, NULL);
  }

  const avr_cycle_count_t end = (avr_cycle_count_t)(run_ms * 1000.0 * g_cycles_per_us);
  const clock_t cpu0 = clock();
  int state = cpu_Running;
  while (g_avr->cycle < end) {
    while (g_xon && g_next_input < g_ninput && g_input[g_next_input].at <= g_avr->cycle) {
      avr_raise_irq(uart_input, g_input[g_next_input++].byte);
    }
    state = avr_run(g_avr);
    if (state == cpu_Done || state == cpu_Crashed) break;
  }
  const double cpu_s = (double)(clock() - cpu0) / CLOCKS_PER_SEC;

  printf("elf: %s (%s at %lu Hz)\n", elf, mcu, freq);
  printf("simulated: %.1f ms (%" PRIu64 " cycles) in %.2f s of host CPU\n",
         cycles_to_us(g_avr->cycle) / 1000.0, (uint64_t)g_avr->cycle, cpu_s);
  printf("uart: %zu of %zu input bytes delivered, %" PRIu64 " output bytes\n", g_next_input,
         g_ninput, g_uart_out_n);
  if (g_npins) printf("pulses: %" PRIu64 " on %d pins\n", g_pulses_n, g_npins);
  int status = 0;
  if (state == cpu_Crashed) {
    printf("FAIL: the AVR crashed\n");
    status = 1;
  }
  if (g_have_busy) {
    if (g_busy_n == 0) {
      printf("FAIL: no high pulse on busy pin %c%d\n", g_busy.port, g_busy.bit);
      status = 1;
    } else {
      const double mean = (double)g_busy_sum / (double)g_busy_n;
      printf("control update (busy pin %c%d high): n=%" PRIu64 " cycles min=%" PRIu64
             " mean=%.0f max=%" PRIu64 "\n",
             g_busy.port, g_busy.bit, g_busy_n, g_busy_min, mean, g_busy_max);
      printf("control update time: min=%.1f us mean=%.1f us max=%.1f us at %.0f MHz\n",
             cycles_to_us(g_busy_min), mean / g_cycles_per_us, cycles_to_us(g_busy_max),
             g_cycles_per_us);
      if (budget_us > 0) {
        const int ok = cycles_to_us(g_busy_max) <= budget_us;
        printf("budget: %.0f us: %s\n", budget_us, ok ? "OK" : "FAIL (over budget)");
        if (!ok) status = 1;
      }
    }
  }
  if (g_uart_out && g_uart_out != stdout) fclose(g_uart_out);
  if (g_pulses_out) fclose(g_pulses_out);
  avr_terminate(g_avr);
  return status;
}
