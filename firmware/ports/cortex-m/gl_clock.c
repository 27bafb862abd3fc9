/**
 * @file gl_clock.c
 * @brief SysTick millisecond clock (see gl_clock.h). Under QEMU without -icount it follows wall time.
 */
#include "gl_clock.h"

#include "board.h"

#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
#define SYST_CSR_ENABLE_TICKINT_CORECLK 0x7u

static volatile uint32_t ms_low;
static volatile uint32_t ms_high;

void gl_clock_init(void)
{
    SYST_RVR = gl_board_core_hz / 1000u - 1u;
    SYST_CVR = 0u;
    SYST_CSR = SYST_CSR_ENABLE_TICKINT_CORECLK;
}

void gl_clock_isr(void)
{
    uint32_t next = ms_low + 1u;
    if (next == 0u) {
        ms_high = ms_high + 1u;
    }
    ms_low = next;
}

uint32_t gl_clock_ms(void)
{
    return ms_low;
}

uint64_t gl_clock_us(void)
{
    uint32_t hi, lo;
    do {
        hi = ms_high;
        lo = ms_low;
    } while (hi != ms_high);
    return (((uint64_t)hi << 32) | lo) * 1000u;
}
