/**
 * @file board_netduinoplus2.c
 * @brief Netduino Plus 2 (STM32F405): USART1 at 0x40011000, IRQ 37, interrupt driven.
 *
 * RXNE raises the interrupt while a byte waits in DR. Transmission writes DR while TXE says it can take
 * a byte (never waiting for it) and leaves the rest to the TXE interrupt (TXEIE), cleared when the ring is
 * empty. A receive overrun (ORE) is cleared by reading SR then DR, which the receive path does anyway.
 * QEMU 7.2's model transmits synchronously (TXE stays set) and has no transmit interrupt, so there every
 * queued byte leaves at once; it drops bytes received before UE and RE are set: the image enables the
 * USART before it prints its banner, so a client that waits for the banner loses nothing.
 */
#include <stdint.h>

#include "board.h"
#include "gl_nvic.h"
#include "gl_uart.h"

#define USART1_BASE 0x40011000u
#define USART_SR (*(volatile uint32_t *)(USART1_BASE + 0x00u))
#define USART_DR (*(volatile uint32_t *)(USART1_BASE + 0x04u))
#define USART_CR1 (*(volatile uint32_t *)(USART1_BASE + 0x0Cu))
#define USART_SR_ORE (1u << 3)
#define USART_SR_RXNE (1u << 5)
#define USART_SR_TXE (1u << 7)
#define USART_CR1_UE (1u << 13)
#define USART_CR1_TXEIE (1u << 7)
#define USART_CR1_RXNEIE (1u << 5)
#define USART_CR1_TE (1u << 3)
#define USART_CR1_RE (1u << 2)
#define IRQ_USART1 37u

const char gl_board_name[] = "netduinoplus2";
const uint32_t gl_board_core_hz = 168000000u;

void gl_board_uart_init(void)
{
    USART_CR1 = USART_CR1_UE | USART_CR1_TE | USART_CR1_RE | USART_CR1_RXNEIE;
    gl_nvic_enable(IRQ_USART1);
}

/** Write DR while it can take a byte; leave the rest to the TXE interrupt. */
static void transmit(void)
{
    uint8_t byte;
    while ((USART_SR & USART_SR_TXE) != 0u && gl_uart_isr_tx_next(&byte)) {
        USART_DR = byte;
    }
    if (gl_uart_isr_tx_pending()) {
        USART_CR1 |= USART_CR1_TXEIE;
    } else {
        USART_CR1 &= ~USART_CR1_TXEIE;
    }
}

void gl_board_uart_start_tx(void)
{
    transmit();
}

int gl_board_irq(uint32_t irq)
{
    if (irq != IRQ_USART1) {
        return -1;
    }
    uint32_t sr = USART_SR;
    if ((sr & USART_SR_ORE) != 0u) {
        gl_uart_isr_overrun();
    }
    if ((sr & (USART_SR_RXNE | USART_SR_ORE)) != 0u) {
        gl_uart_isr_rx((uint8_t)USART_DR);
    }
    if ((USART_CR1 & USART_CR1_TXEIE) != 0u) {
        transmit();
    }
    return 0;
}
