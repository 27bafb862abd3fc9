/**
 * @file board_mps2_an505.c
 * @brief Arm MPS2 AN505 (Cortex-M33 in the IoT Kit, single-precision FPU), Secure state: CMSDK APB UART0 (gl_cmsdk_uart.c), interrupt driven.
 *
 * The image runs in Secure state with the SAU off (everything Secure) and uses the Secure aliases: UART0 at
 * 0x50200000 (expansion interrupts 32 and 33 carry its receive and transmit lines; the handler serves both
 * on either), the IoT Kit's CMSDK timer 1 at 0x50001000 wakes the emulator. Core clock 20 MHz.
 */
#include <stdint.h>

#include "board.h"
#include "gl_cmsdk_uart.h"

const gl_cmsdk_uart_t gl_board_console = {
    .base = 0x50200000u,
    .irq_rx = 32u,
    .irq_tx = 33u,
    .bauddiv = 16u,
    .wake_timer = 0x50001000u,
};

const char gl_board_name[] = "mps2-an505";
const uint32_t gl_board_core_hz = 20000000u;
