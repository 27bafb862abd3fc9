/**
 * @file board_microbit.c
 * @brief BBC micro:bit (nRF51822, Cortex-M0, 16 MHz, 256 KiB flash, 16 KiB RAM): UART0 at 0x40002000, IRQ 2.
 *
 * The nRF51 UART signals each received byte (EVENTS_RXDRDY, byte in RXD) and each byte sent (EVENTS_TXDRDY);
 * events stay set until written 0, and the interrupt is the OR of the enabled events. Transmission writes
 * the first byte to TXD and continues from the TXDRDY interrupt. Reading RXD takes the byte and raises
 * RXDRDY again when more are waiting, so the event is cleared before each read. The pins are left as QEMU
 * models them (it ignores PSEL*); on a real board PSELTXD/PSELRXD would select pins 24 and 25.
 */
#include <stdint.h>

#include "board.h"
#include "gl_nvic.h"
#include "gl_uart.h"

#define UART0_BASE 0x40002000u
#define UART_REG(off) (*(volatile uint32_t *)(UART0_BASE + (off)))
#define TASKS_STARTRX UART_REG(0x000u)
#define TASKS_STARTTX UART_REG(0x008u)
#define EVENTS_RXDRDY UART_REG(0x108u)
#define EVENTS_TXDRDY UART_REG(0x11Cu)
#define EVENTS_ERROR UART_REG(0x124u)
#define INTENSET UART_REG(0x304u)
#define ERRORSRC UART_REG(0x480u)
#define ENABLE UART_REG(0x500u)
#define RXD UART_REG(0x518u)
#define TXD UART_REG(0x51Cu)
#define BAUDRATE UART_REG(0x524u)

#define ENABLE_UART 4u
#define BAUDRATE_115200 0x01D7E000u
#define INT_RXDRDY (1u << 2)
#define INT_TXDRDY (1u << 7)
#define INT_ERROR (1u << 9)
#define IRQ_UART0 2u

const char gl_board_name[] = "microbit";
const uint32_t gl_board_core_hz = 16000000u;

static volatile int tx_active; /* a byte is being sent; the TXDRDY interrupt will take the next */

void gl_board_uart_init(void)
{
    tx_active = 0;
    ENABLE = ENABLE_UART;
    BAUDRATE = BAUDRATE_115200;
    EVENTS_RXDRDY = 0u;
    EVENTS_TXDRDY = 0u;
    EVENTS_ERROR = 0u;
    INTENSET = INT_RXDRDY | INT_TXDRDY | INT_ERROR;
    TASKS_STARTRX = 1u;
    TASKS_STARTTX = 1u;
    gl_nvic_enable(IRQ_UART0);
}

void gl_board_uart_start_tx(void)
{
    uint8_t byte;
    if (!tx_active && gl_uart_isr_tx_next(&byte)) {
        tx_active = 1;
        TXD = byte;
    }
}

int gl_board_irq(uint32_t irq)
{
    if (irq != IRQ_UART0) {
        return -1;
    }
    while (EVENTS_RXDRDY != 0u) {
        EVENTS_RXDRDY = 0u;
        gl_uart_isr_rx((uint8_t)RXD);
    }
    if (EVENTS_ERROR != 0u) {
        EVENTS_ERROR = 0u;
        ERRORSRC = ERRORSRC; /* write one to clear what was flagged */
        gl_uart_isr_overrun();
    }
    if (EVENTS_TXDRDY != 0u) {
        uint8_t byte;
        EVENTS_TXDRDY = 0u;
        if (gl_uart_isr_tx_next(&byte)) {
            TXD = byte;
        } else {
            tx_active = 0;
        }
    }
    return 0;
}
