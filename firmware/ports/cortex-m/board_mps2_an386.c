/**
 * @file board_mps2_an386.c
 * @brief Arm MPS2 AN386 (Cortex-M4F): CMSDK APB UART0 (gl_cmsdk_uart.c), interrupt driven.
 *
 * UART0's receive interrupt is IRQ 0 and its transmit interrupt IRQ 1 (QEMU's mps2.c, as the FPGA image);
 * CMSDK timer 1 (unused otherwise) wakes the emulator.
 */
#include <stdint.h>

#include "board.h"
#include "gl_cmsdk_uart.h"

const gl_cmsdk_uart_t gl_board_console = {
    .base = 0x40004000u,
    .irq_rx = 0u,
    .irq_tx = 1u,
    .bauddiv = 16u,
    .wake_timer = 0x40001000u,
};

const char gl_board_name[] = "mps2-an386";
const uint32_t gl_board_core_hz = 25000000u;
