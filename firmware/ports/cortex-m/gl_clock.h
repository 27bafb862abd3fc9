/**
 * @file gl_clock.h
 * @brief Millisecond clock from SysTick (1 kHz interrupt on the core clock).
 */
#ifndef GAINLINK_GL_CLOCK_H
#define GAINLINK_GL_CLOCK_H

#include <stdint.h>

/** @brief Start SysTick at 1 kHz from gl_board_core_hz. */
void gl_clock_init(void);

/** @brief Milliseconds since gl_clock_init() (wraps after 49 days). */
uint32_t gl_clock_ms(void);

/** @brief Microseconds since gl_clock_init(), millisecond resolution, 64-bit. */
uint64_t gl_clock_us(void);

/** @brief SysTick exception handler (in the vector table). */
void gl_clock_isr(void);

#endif /* GAINLINK_GL_CLOCK_H */
