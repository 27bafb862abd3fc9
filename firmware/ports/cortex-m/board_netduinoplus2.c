/**
 * @file board_netduinoplus2.c
 * @brief Netduino Plus 2 (STM32F405): USART1 at 0x40011000.
 */
#include <stdint.h>

#include "board.h"

#define USART1_BASE 0x40011000u
#define USART_SR (*(volatile uint32_t *)(USART1_BASE + 0x00u))
#define USART_DR (*(volatile uint32_t *)(USART1_BASE + 0x04u))
#define USART_CR1 (*(volatile uint32_t *)(USART1_BASE + 0x0Cu))
#define USART_SR_TXE (1u << 7)
#define USART_CR1_UE (1u << 13)
#define USART_CR1_TE (1u << 3)
#define USART_CR1_RE (1u << 2)

const char gl_board_name[] = "netduinoplus2";

void gl_board_uart_init(void)
{
    USART_CR1 = USART_CR1_UE | USART_CR1_TE | USART_CR1_RE;
}

void gl_board_uart_putc(char c)
{
    while ((USART_SR & USART_SR_TXE) == 0u) {
    }
    USART_DR = (uint32_t)(uint8_t)c;
}
