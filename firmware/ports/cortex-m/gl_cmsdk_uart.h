/**
 * @file gl_cmsdk_uart.h
 * @brief The Arm CMSDK APB UART, interrupt driven: the console of the MPS2 and MPS3 boards (board_mps*.c).
 *
 * The CMSDK UART raises its transmit interrupt when a byte has left the data register (TXFULL going from
 * set to clear), so transmission is started by writing the first byte and continued from the interrupt;
 * both interrupt flags stay set until written to INTCLEAR. The receive and transmit interrupts have their
 * own NVIC lines; the handler reads INTSTATUS and serves both on either line, so a board only lists them.
 */
#ifndef GAINLINK_GL_CMSDK_UART_H
#define GAINLINK_GL_CMSDK_UART_H

#include <stdint.h>

/** Where a board's console UART sits. */
typedef struct gl_cmsdk_uart {
    uintptr_t base;       /**< UART register block. */
    uint32_t irq_rx;      /**< NVIC line of its receive interrupt. */
    uint32_t irq_tx;      /**< NVIC line of its transmit interrupt. */
    uint32_t bauddiv;     /**< BAUDDIV (>= 16; the emulator ignores it). */
    uintptr_t wake_timer; /**< A CMSDK APB timer the driver may rearm to wake the emulator (0: none). */
} gl_cmsdk_uart_t;

/** The board's console UART, defined by its board file (board_mps*.c); the board hooks of board.h
 * (gl_board_uart_init(), gl_board_uart_start_tx(), gl_board_irq()) serve it, in gl_cmsdk_uart.c. */
extern const gl_cmsdk_uart_t gl_board_console;

/** @brief Enable transmit, receive and both interrupts, in the UART and the NVIC. @param[in] u The UART. */
void gl_cmsdk_uart_init(const gl_cmsdk_uart_t *u);

/** @brief Start transmitting if the transmitter is idle (see gl_board_uart_start_tx()). @param[in] u The UART. */
void gl_cmsdk_uart_start_tx(const gl_cmsdk_uart_t *u);

/**
 * @brief The board's interrupt handler for this UART.
 * @param[in] u   The UART.
 * @param[in] irq External interrupt number.
 * @return 0 when `irq` is one of the UART's lines (served), -1 otherwise.
 */
int gl_cmsdk_uart_irq(const gl_cmsdk_uart_t *u, uint32_t irq);

#endif /* GAINLINK_GL_CMSDK_UART_H */
