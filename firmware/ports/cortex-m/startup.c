/**
 * @file startup.c
 * @brief Cortex-M start-up: vector table, .data/.bss set-up, FPU enable and self-test, fault exits.
 *
 * On a core with an FPU (__ARM_FP: M4, M7, M33, M55) the FPU is enabled (CPACR CP10/CP11 full access;
 * on the M55 that also enables Helium) before any float instruction can run. The self-test reads CPACR
 * back and stops the simulator with GL_EXIT_FPU if the FPU is still disabled, instead of letting the first
 * float instruction fault (GL_SKIP_FPU_ENABLE builds exercise this path). Soft-float builds (M0, M3) have
 * no FPU to enable and never touch CPACR (ARMv6-M has none). Every fault handler stops the simulator with
 * GL_EXIT_FAULT rather than spinning. ARMv8-M images (M33, M55) start and stay in Secure state with the
 * SAU off, so every address is Secure and nothing needs configuring.
 *
 * SysTick drives the millisecond clock (gl_clock.c); every external interrupt goes through one handler
 * that reads its number from IPSR and hands it to the board (gl_board_irq()); one the board does not
 * expect is a fault.
 */
#include <stdint.h>

#include "board.h"
#include "gl_clock.h"
#include "semihost.h"

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)
#define CPACR_CP10_CP11_FULL (0xFu << 20)

extern uint32_t _data_load, _data_start, _data_end, _bss_start, _bss_end, _stack_top;
int main(void);
void gl_reset_handler(void);
void gl_fault_handler(void);
void gl_irq_handler(void);

/** External interrupts in the vector table: the STM32F405 has 82, the MPS2 boards 32, the AN505 and AN547
 *  up to 124 and 128 (their expansion lines start at 32), QEMU's ARMv7-M NVIC 96; ARMv6-M uses 32. */
#define GL_EXTERNAL_IRQS 128

void gl_fault_handler(void)
{
    gl_sh_exit(GL_EXIT_FAULT);
}

void gl_reset_handler(void)
{
    const volatile uint32_t *src = &_data_load;
    for (volatile uint32_t *dst = &_data_start; dst < &_data_end;) {
        *dst++ = *src++;
    }
    for (volatile uint32_t *dst = &_bss_start; dst < &_bss_end;) {
        *dst++ = 0u;
    }
#if defined(__ARM_FP)
#ifndef GL_SKIP_FPU_ENABLE
    SCB_CPACR |= CPACR_CP10_CP11_FULL;
    __asm__ volatile("dsb\n\tisb" ::: "memory");
#endif
    if ((SCB_CPACR & CPACR_CP10_CP11_FULL) != CPACR_CP10_CP11_FULL) {
        gl_sh_exit(GL_EXIT_FPU);
    }
#endif
    gl_sh_exit((uint32_t)main());
}

void gl_irq_handler(void)
{
    uint32_t ipsr;
    __asm__ volatile("mrs %0, ipsr" : "=r"(ipsr));
    if (ipsr < 16u || gl_board_irq(ipsr - 16u) != 0) {
        gl_sh_exit(GL_EXIT_FAULT);
    }
}

typedef void (*gl_vector_t)(void);

__attribute__((section(".isr_vector"), used)) static const gl_vector_t vectors[16 + GL_EXTERNAL_IRQS] = {
    [0] = (gl_vector_t)(uintptr_t)&_stack_top,
    [1] = gl_reset_handler,
    [2] = gl_fault_handler,  /* NMI */
    [3] = gl_fault_handler,  /* HardFault */
    [4] = gl_fault_handler,  /* MemManage */
    [5] = gl_fault_handler,  /* BusFault */
    [6] = gl_fault_handler,  /* UsageFault */
    [7] = gl_fault_handler,  /* SecureFault (ARMv8-M) */
    [11] = gl_fault_handler, /* SVCall */
    [12] = gl_fault_handler, /* DebugMonitor */
    [14] = gl_fault_handler, /* PendSV */
    [15] = gl_clock_isr,     /* SysTick */
    [16 ... 16 + GL_EXTERNAL_IRQS - 1] = gl_irq_handler,
};
