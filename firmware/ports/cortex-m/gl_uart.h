/**
 * @file gl_uart.h
 * @brief Interrupt-driven console UART: a receive and a transmit ring, no busy wait, no malloc.
 *
 * The board's interrupt handler (board.h) moves bytes between the UART registers and the rings; the
 * main loop reads and writes the rings without ever waiting for the hardware. A byte that arrives
 * when the receive ring is full is dropped and counted (`rx_overruns`, with the UART's own overruns);
 * gl_uart_write() takes a whole message or nothing and counts what it refused (`tx_dropped`).
 * One producer and one consumer per ring (the handler and the main loop), so the indices need no lock.
 */
#ifndef GAINLINK_GL_UART_H
#define GAINLINK_GL_UART_H

#include <stddef.h>
#include <stdint.h>

/** Receive ring size (power of two). */
#define GL_UART_RX_SIZE 1024u
/** Transmit ring size (power of two). */
#define GL_UART_TX_SIZE 2048u

_Static_assert((GL_UART_RX_SIZE & (GL_UART_RX_SIZE - 1u)) == 0u, "GL_UART_RX_SIZE must be a power of two");
_Static_assert((GL_UART_TX_SIZE & (GL_UART_TX_SIZE - 1u)) == 0u, "GL_UART_TX_SIZE must be a power of two");

/** UART counters. */
typedef struct gl_uart_stats {
    uint32_t rx_bytes;     /**< Bytes received into the ring. */
    uint32_t rx_overruns;  /**< Bytes lost: receive ring full, or the UART's own overrun flag. */
    uint32_t tx_bytes;     /**< Bytes queued for transmission. */
    uint32_t tx_dropped;   /**< Bytes refused by gl_uart_write() (ring full). */
} gl_uart_stats_t;

/** @brief Reset the rings and counters and start the board's UART (gl_board_uart_init()). */
void gl_uart_init(void);

/**
 * @brief Take received bytes (never waits).
 * @param[out] buf Destination.
 * @param[in]  cap Its size.
 * @return Bytes copied (0 when none are waiting).
 */
size_t gl_uart_read(uint8_t *buf, size_t cap);

/** @brief 1 when received bytes are waiting (for the sleep check). */
int gl_uart_rx_ready(void);

/**
 * @brief Queue `len` bytes for transmission, all or none (never waits).
 * @param[in] bytes Data.
 * @param[in] len   Length.
 * @return 0 queued, -1 refused (not enough room; counted in tx_dropped).
 */
int gl_uart_write(const uint8_t *bytes, size_t len);

/** @brief Room left in the transmit ring, bytes. */
size_t gl_uart_tx_room(void);

/**
 * @brief Wait (sleeping between interrupts) until the transmit ring has drained, at most `timeout_ms`.
 *        For the end of a run, never the control path.
 * @param[in] timeout_ms Bound.
 * @return 0 drained, -1 timed out.
 */
int gl_uart_flush(uint32_t timeout_ms);

/** @brief Copy of the counters. @param[out] stats Counters. */
void gl_uart_stats(gl_uart_stats_t *stats);

/* --- for the board's interrupt handler only ------------------------------------------------------ */

/** @brief A byte arrived (drops and counts it when the ring is full). @param[in] byte Byte. */
void gl_uart_isr_rx(uint8_t byte);

/**
 * @brief The next byte to transmit.
 * @param[out] byte Byte.
 * @return 1 when there is one, 0 when the ring is empty.
 */
int gl_uart_isr_tx_next(uint8_t *byte);

/** @brief 1 when bytes wait in the transmit ring. */
int gl_uart_isr_tx_pending(void);

/** @brief The UART reported a receive overrun (a byte lost in the hardware). */
void gl_uart_isr_overrun(void);

#endif /* GAINLINK_GL_UART_H */
