/**
 * @file gl_cmsdk_uart.c
 * @brief The Arm CMSDK APB UART, interrupt driven (see gl_cmsdk_uart.h).
 */
#include "board.h"
#include "gl_cmsdk_uart.h"

#include "gl_nvic.h"
#include "gl_uart.h"

#define REG(u, off) (*(volatile uint32_t *)((u)->base + (off)))
#define UART_DATA 0x00u
#define UART_STATE 0x04u
#define UART_CTRL 0x08u
#define UART_INTSTATUS 0x0Cu /* read: INTSTATUS, write: INTCLEAR */
#define UART_BAUDDIV 0x10u

#define STATE_RX_FULL 0x2u
#define STATE_RX_OVERRUN 0x8u
#define CTRL_TX_EN 0x1u
#define CTRL_RX_EN 0x2u
#define CTRL_TX_INTEN 0x4u
#define CTRL_RX_INTEN 0x8u
#define INT_TX 0x1u
#define INT_RX 0x2u

#define TIMER_CTRL 0x00u
#define TIMER_VALUE 0x04u
#define TIMER_RELOAD 0x08u
#define TIMER_CTRL_ENABLE 0x1u

static volatile int tx_active; /* a byte is in the data register; the TX interrupt will take the next */

void gl_cmsdk_uart_init(const gl_cmsdk_uart_t *u)
{
    tx_active = 0;
    REG(u, UART_BAUDDIV) = u->bauddiv;
    REG(u, UART_INTSTATUS) = INT_TX | INT_RX;
    REG(u, UART_CTRL) = CTRL_TX_EN | CTRL_RX_EN | CTRL_TX_INTEN | CTRL_RX_INTEN;
    gl_nvic_enable(u->irq_rx);
    gl_nvic_enable(u->irq_tx);
}

void gl_cmsdk_uart_start_tx(const gl_cmsdk_uart_t *u)
{
    uint8_t byte;
    if (!tx_active && gl_uart_isr_tx_next(&byte)) {
        tx_active = 1;
        REG(u, UART_DATA) = byte;
    }
}

/**
 * QEMU's CMSDK UART model takes the next received byte only when its event loop runs again, and reading
 * DATA does not wake that loop (the STM32 model's read does). Rearming an otherwise unused timer (interrupt
 * disabled) one tick ahead does wake it; measured on the AN386 it takes the receive path from ~80 to ~30 us
 * per byte. On hardware it is a harmless write to an idle timer.
 */
static void wake_emulator(const gl_cmsdk_uart_t *u)
{
    if (u->wake_timer == 0u) {
        return;
    }
    *(volatile uint32_t *)(u->wake_timer + TIMER_RELOAD) = 0xFFFFFFFFu;
    *(volatile uint32_t *)(u->wake_timer + TIMER_VALUE) = 1u;
    *(volatile uint32_t *)(u->wake_timer + TIMER_CTRL) = TIMER_CTRL_ENABLE;
}

static void rx_interrupt(const gl_cmsdk_uart_t *u)
{
    REG(u, UART_INTSTATUS) = INT_RX; /* before reading: a byte arriving meanwhile raises it again */
    while ((REG(u, UART_STATE) & STATE_RX_FULL) != 0u) {
        gl_uart_isr_rx((uint8_t)REG(u, UART_DATA));
    }
    wake_emulator(u);
    if ((REG(u, UART_STATE) & STATE_RX_OVERRUN) != 0u) {
        REG(u, UART_STATE) = STATE_RX_OVERRUN; /* write one to clear */
        gl_uart_isr_overrun();
    }
}

static void tx_interrupt(const gl_cmsdk_uart_t *u)
{
    uint8_t byte;
    REG(u, UART_INTSTATUS) = INT_TX;
    if (gl_uart_isr_tx_next(&byte)) {
        REG(u, UART_DATA) = byte;
    } else {
        tx_active = 0;
    }
}

int gl_cmsdk_uart_irq(const gl_cmsdk_uart_t *u, uint32_t irq)
{
    if (irq != u->irq_rx && irq != u->irq_tx) {
        return -1;
    }
    const uint32_t status = REG(u, UART_INTSTATUS);
    if ((status & INT_RX) != 0u) {
        rx_interrupt(u);
    }
    if ((status & INT_TX) != 0u) {
        tx_interrupt(u);
    }
    return 0;
}

/* The board hooks of board.h for every CMSDK board: its console UART is the one the board file describes. */
void gl_board_uart_init(void)
{
    gl_cmsdk_uart_init(&gl_board_console);
}

void gl_board_uart_start_tx(void)
{
    gl_cmsdk_uart_start_tx(&gl_board_console);
}

int gl_board_irq(uint32_t irq)
{
    return gl_cmsdk_uart_irq(&gl_board_console, irq);
}
