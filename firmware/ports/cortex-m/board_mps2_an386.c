/**
 * @file board_mps2_an386.c
 * @brief Arm MPS2 AN386 (Cortex-M4): CMSDK APB UART0 at 0x40004000, interrupt driven.
 *
 * UART0's receive interrupt is IRQ 0 and its transmit interrupt IRQ 1 (QEMU's mps2.c, as the FPGA image).
 * The CMSDK UART raises its transmit interrupt when a byte has left the data register (TXFULL going
 * from set to clear), so transmission is started by writing the first byte and continued from the
 * interrupt; both interrupt flags stay set until written to INTCLEAR.
 */
#include <stdint.h>

#include "board.h"
#include "gl_nvic.h"
#include "gl_uart.h"

#define UART0_BASE 0x40004000u
#define UART_DATA (*(volatile uint32_t *)(UART0_BASE + 0x00u))
#define UART_STATE (*(volatile uint32_t *)(UART0_BASE + 0x04u))
#define UART_CTRL (*(volatile uint32_t *)(UART0_BASE + 0x08u))
#define UART_INTCLEAR (*(volatile uint32_t *)(UART0_BASE + 0x0Cu))
#define UART_BAUDDIV (*(volatile uint32_t *)(UART0_BASE + 0x10u))

#define STATE_RX_FULL 0x2u
#define STATE_RX_OVERRUN 0x8u
#define CTRL_TX_EN 0x1u
#define CTRL_RX_EN 0x2u
#define CTRL_TX_INTEN 0x4u
#define CTRL_RX_INTEN 0x8u
#define INT_TX 0x1u
#define INT_RX 0x2u
#define TIMER1_BASE 0x40001000u
#define TIMER_CTRL (*(volatile uint32_t *)(TIMER1_BASE + 0x00u))
#define TIMER_VALUE (*(volatile uint32_t *)(TIMER1_BASE + 0x04u))
#define TIMER_RELOAD (*(volatile uint32_t *)(TIMER1_BASE + 0x08u))
#define TIMER_CTRL_ENABLE 0x1u
#define IRQ_UART0_RX 0u
#define IRQ_UART0_TX 1u

const char gl_board_name[] = "mps2-an386";
const uint32_t gl_board_core_hz = 25000000u;

static volatile int tx_active; /* a byte is in the data register; the TX interrupt will take the next */

void gl_board_uart_init(void)
{
    tx_active = 0;
    UART_BAUDDIV = 16u;
    UART_INTCLEAR = INT_TX | INT_RX;
    UART_CTRL = CTRL_TX_EN | CTRL_RX_EN | CTRL_TX_INTEN | CTRL_RX_INTEN;
    gl_nvic_enable(IRQ_UART0_RX);
    gl_nvic_enable(IRQ_UART0_TX);
}

void gl_board_uart_start_tx(void)
{
    uint8_t byte;
    if (!tx_active && gl_uart_isr_tx_next(&byte)) {
        tx_active = 1;
        UART_DATA = byte;
    }
}

/**
 * QEMU's CMSDK UART model takes the next received byte only when its event loop runs again, and reading
 * DATA does not wake that loop (the STM32 model's read does). Rearming an otherwise unused timer
 * (CMSDK timer 1, interrupt disabled) one tick ahead does wake it; measured here it takes the receive
 * path from ~80 to ~30 us per byte. On hardware it is a harmless write to an idle timer.
 */
static void wake_emulator(void)
{
    TIMER_RELOAD = 0xFFFFFFFFu;
    TIMER_VALUE = 1u;
    TIMER_CTRL = TIMER_CTRL_ENABLE;
}

static void rx_interrupt(void)
{
    UART_INTCLEAR = INT_RX; /* before reading: a byte arriving meanwhile raises it again */
    while ((UART_STATE & STATE_RX_FULL) != 0u) {
        gl_uart_isr_rx((uint8_t)UART_DATA);
    }
    wake_emulator();
    if ((UART_STATE & STATE_RX_OVERRUN) != 0u) {
        UART_STATE = STATE_RX_OVERRUN; /* write one to clear */
        gl_uart_isr_overrun();
    }
}

static void tx_interrupt(void)
{
    uint8_t byte;
    UART_INTCLEAR = INT_TX;
    if (gl_uart_isr_tx_next(&byte)) {
        UART_DATA = byte;
    } else {
        tx_active = 0;
    }
}

int gl_board_irq(uint32_t irq)
{
    if (irq == IRQ_UART0_RX) {
        rx_interrupt();
        return 0;
    }
    if (irq == IRQ_UART0_TX) {
        tx_interrupt();
        return 0;
    }
    return -1;
}
