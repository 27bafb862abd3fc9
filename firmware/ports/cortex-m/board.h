/**
 * @file board.h
 * @brief What a board file provides to the Cortex-M port: its name and a polled UART.
 */
#ifndef GAINLINK_BOARD_H
#define GAINLINK_BOARD_H

/** Board name, e.g. "mps2-an386". */
extern const char gl_board_name[];

/** @brief Enable the console UART (transmit and receive). */
void gl_board_uart_init(void);

/** @brief Send one byte on the console UART (blocking). @param[in] c Byte. */
void gl_board_uart_putc(char c);

#endif /* GAINLINK_BOARD_H */
