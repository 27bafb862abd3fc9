/**
 * @file board_mps3_an547.c
 * @brief Arm MPS3 AN547 (Cortex-M55 in the SSE-300, FPU and Helium), Secure state: CMSDK APB UART0 (gl_cmsdk_uart.c), interrupt driven.
 *
 * The image runs in Secure state with the SAU off and uses the Secure alias of UART0 (0x59303000; lines 33
 * and 34, served together). The SSE-300 has no CMSDK APB timer to wake the emulator with, so received bytes
 * wait for QEMU's own event loop (slower, not wrong). Core clock 32 MHz.
 */
#include <stdint.h>

#include "board.h"
#include "gl_cmsdk_uart.h"

const gl_cmsdk_uart_t gl_board_console = {
    .base = 0x59303000u,
    .irq_rx = 33u,
    .irq_tx = 34u,
    .bauddiv = 16u,
    .wake_timer = 0u,
};

const char gl_board_name[] = "mps3-an547";
const uint32_t gl_board_core_hz = 32000000u;
