/**
 * @file gl_uart.c
 * @brief Receive and transmit rings of the console UART (see gl_uart.h).
 */
#include "gl_uart.h"

#include <string.h>

#include "board.h"
#include "gl_clock.h"
#include "gl_nvic.h"

/* Free-running indices (wrap at 2^32; size is a power of two). head is written by the producer only,
 * tail by the consumer only; a compiler barrier orders the data before the index that publishes it. */
#define BARRIER() __asm__ volatile("" ::: "memory")

static uint8_t rx_buf[GL_UART_RX_SIZE];
static uint8_t tx_buf[GL_UART_TX_SIZE];
static volatile uint32_t rx_head, rx_tail, tx_head, tx_tail;
static volatile gl_uart_stats_t stats;

void gl_uart_init(void)
{
    rx_head = rx_tail = tx_head = tx_tail = 0u;
    memset((void *)&stats, 0, sizeof stats);
    gl_board_uart_init();
}

void gl_uart_isr_rx(uint8_t byte)
{
    uint32_t head = rx_head;
    if (head - rx_tail >= GL_UART_RX_SIZE) {
        stats.rx_overruns++;
        return;
    }
    rx_buf[head & (GL_UART_RX_SIZE - 1u)] = byte;
    BARRIER();
    rx_head = head + 1u;
    stats.rx_bytes++;
}

void gl_uart_isr_overrun(void)
{
    stats.rx_overruns++;
}

int gl_uart_isr_tx_next(uint8_t *byte)
{
    uint32_t tail = tx_tail;
    if (tail == tx_head) {
        return 0;
    }
    *byte = tx_buf[tail & (GL_UART_TX_SIZE - 1u)];
    BARRIER();
    tx_tail = tail + 1u;
    return 1;
}

int gl_uart_isr_tx_pending(void)
{
    return tx_head != tx_tail;
}

size_t gl_uart_read(uint8_t *buf, size_t cap)
{
    uint32_t tail = rx_tail;
    uint32_t avail = rx_head - tail;
    BARRIER();
    size_t n = avail < cap ? avail : cap;
    for (size_t i = 0; i < n; ++i) {
        buf[i] = rx_buf[(tail + (uint32_t)i) & (GL_UART_RX_SIZE - 1u)];
    }
    BARRIER();
    rx_tail = tail + (uint32_t)n;
    return n;
}

int gl_uart_rx_ready(void)
{
    return rx_head != rx_tail;
}

size_t gl_uart_tx_room(void)
{
    return GL_UART_TX_SIZE - (tx_head - tx_tail);
}

int gl_uart_write(const uint8_t *bytes, size_t len)
{
    if (len > gl_uart_tx_room()) {
        stats.tx_dropped += (uint32_t)len;
        return -1;
    }
    uint32_t head = tx_head;
    for (size_t i = 0; i < len; ++i) {
        tx_buf[(head + (uint32_t)i) & (GL_UART_TX_SIZE - 1u)] = bytes[i];
    }
    BARRIER();
    tx_head = head + (uint32_t)len;
    stats.tx_bytes += (uint32_t)len;
    uint32_t primask = gl_irq_save();
    gl_board_uart_start_tx();
    gl_irq_restore(primask);
    return 0;
}

static int tx_drained(void)
{
    return tx_head == tx_tail;
}

int gl_uart_flush(uint32_t timeout_ms)
{
    uint32_t start = gl_clock_ms();
    while (!tx_drained()) {
        if (gl_clock_ms() - start >= timeout_ms) {
            return -1;
        }
        gl_wait_for_interrupt(tx_drained);
    }
    return 0;
}

void gl_uart_stats(gl_uart_stats_t *out)
{
    memcpy(out, (const void *)&stats, sizeof *out);
}
