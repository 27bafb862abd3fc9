/**
 * @file board.h
 * @brief What a board file provides to the Cortex-M port: its name, core clock, console UART and IRQs.
 *
 * The board file drives the UART registers; the byte queues and their API are board-independent
 * (gl_uart.h). Its interrupt handler moves bytes between the registers and the queues with
 * gl_uart_isr_rx() / gl_uart_isr_tx_next(), and counts hardware overruns with gl_uart_isr_overrun().
 */
#ifndef GAINLINK_BOARD_H
#define GAINLINK_BOARD_H

#include <stdint.h>

/** Board name, e.g. "mps2-an386". */
extern const char gl_board_name[];

/** Core clock (SysTick counts it), Hz. */
extern const uint32_t gl_board_core_hz;

/** @brief Enable the console UART (8N1, transmit and receive) and its receive interrupt, in the UART and the NVIC. */
void gl_board_uart_init(void);

/**
 * @brief Start transmitting if the transmitter is idle (called with interrupts masked after bytes were queued).
 *        The transmit interrupt then takes every queued byte in turn.
 */
void gl_board_uart_start_tx(void);

/**
 * @brief The board's handler of external interrupt `irq` (IPSR - 16).
 * @param[in] irq Interrupt number.
 * @return 0 when handled, -1 for an interrupt the board does not expect.
 */
int gl_board_irq(uint32_t irq);

#endif /* GAINLINK_BOARD_H */
