#include "uart.h"

#include <avr/interrupt.h>
#include <avr/io.h>

#include "protocol_gen.h"

namespace {
// U2X: the UART divides the clock by 8 * (UBRR + 1).
constexpr uint32_t kUbrr = (F_CPU / 8 + eelproto::kBaud / 2) / eelproto::kBaud - 1;
static_assert(kUbrr == 34, "57600 baud at 16 MHz is UBRR 34 with U2X (-0.8 %)");

// Rings of a power-of-two size: an index wraps with a mask. One slot stays empty to tell full
// from empty; head is written by the producer only, tail by the consumer only, each one byte, so
// neither side needs to block interrupts.
constexpr uint8_t kRxSize = 64;
constexpr uint8_t kTxSize = 32;
volatile uint8_t g_rx[kRxSize];
volatile uint8_t g_rx_head, g_rx_tail;
volatile uint8_t g_tx[kTxSize];
volatile uint8_t g_tx_head, g_tx_tail;
}  // namespace

ISR(USART_RX_vect) {
  const uint8_t byte = UDR0;
  const uint8_t next = static_cast<uint8_t>((g_rx_head + 1) & (kRxSize - 1));
  if (next != g_rx_tail) {  // full: the byte is lost, and the frame it belongs to fails its CRC
    g_rx[g_rx_head] = byte;
    g_rx_head = next;
  }
}

ISR(USART_UDRE_vect) {
  const uint8_t tail = g_tx_tail;
  if (tail == g_tx_head) {
    UCSR0B &= static_cast<uint8_t>(~_BV(UDRIE0));  // nothing left: stop asking
    return;
  }
  UDR0 = g_tx[tail];
  g_tx_tail = static_cast<uint8_t>((tail + 1) & (kTxSize - 1));
}

namespace uart {

void begin() {
  UCSR0A = _BV(U2X0);  // before UBRR0: simavr derives the byte time when UBRR0 is written
  UBRR0 = kUbrr;
  UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);  // 8N1
  UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

bool read(uint8_t& byte) {
  const uint8_t tail = g_rx_tail;
  if (tail == g_rx_head) return false;
  byte = g_rx[tail];
  g_rx_tail = static_cast<uint8_t>((tail + 1) & (kRxSize - 1));
  return true;
}

bool can_write() {
  return static_cast<uint8_t>((g_tx_head + 1) & (kTxSize - 1)) != g_tx_tail;
}

void write(uint8_t byte) {
  const uint8_t head = g_tx_head;
  g_tx[head] = byte;
  g_tx_head = static_cast<uint8_t>((head + 1) & (kTxSize - 1));
  UCSR0B |= _BV(UDRIE0);  // the interrupt sends it (and what follows)
}

}  // namespace uart
