/**
 * @file gl_nvic.h
 * @brief The few NVIC and PRIMASK operations the port needs (the same on ARMv6-M, ARMv7-M and ARMv8-M).
 */
#ifndef GAINLINK_GL_NVIC_H
#define GAINLINK_GL_NVIC_H

#include <stdint.h>

#define GL_NVIC_ISER ((volatile uint32_t *)0xE000E100u)

/** @brief Enable external interrupt `irq` in the NVIC. @param[in] irq Interrupt number. */
static inline void gl_nvic_enable(uint32_t irq)
{
    GL_NVIC_ISER[irq >> 5] = 1u << (irq & 31u);
}

/** @brief Mask interrupts (PRIMASK); returns the previous PRIMASK for gl_irq_restore(). */
static inline uint32_t gl_irq_save(void)
{
    uint32_t primask;
    __asm__ volatile("mrs %0, primask\n\tcpsid i" : "=r"(primask)::"memory");
    return primask;
}

/** @brief Restore PRIMASK saved by gl_irq_save(). @param[in] primask Saved value. */
static inline void gl_irq_restore(uint32_t primask)
{
    __asm__ volatile("msr primask, %0" ::"r"(primask) : "memory");
}

/** @brief Sleep until an interrupt is pending unless `ready()` says there is work (checked with interrupts masked). */
static inline void gl_wait_for_interrupt(int (*ready)(void))
{
    __asm__ volatile("cpsid i" ::: "memory");
    if (!ready()) {
        __asm__ volatile("wfi" ::: "memory"); /* a pending interrupt wakes it even while masked */
    }
    __asm__ volatile("cpsie i" ::: "memory");
}

#endif /* GAINLINK_GL_NVIC_H */
