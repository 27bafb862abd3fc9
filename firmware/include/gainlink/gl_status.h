/**
 * @file gl_status.h
 * @brief The status codes of every gainlink call: 0 success, negative errors, positive information.
 *
 * One enum for every law (gl_law.h) and every node: the float32 loop returns it (gl_loop.h), the scheduled loop's
 * own codes have the same values (gl_sched.h), and gl_law.h gives the fixed-point law's steps the same meaning.
 */
#ifndef GAINLINK_GL_STATUS_H
#define GAINLINK_GL_STATUS_H

#ifdef __cplusplus
extern "C" {
#endif

/** Status codes: 0 success, negative errors, positive information. */
typedef enum gl_status {
    GL_OK = 0,              /**< Step done, no input saturated / call succeeded. */
    GL_SATURATED = 1,       /**< Step done, at least one input was clamped. */
    GL_ERR_NULL = -1,       /**< A required pointer was NULL. */
    GL_ERR_NANINF = -2,     /**< Non-finite measurement/reference (step) or gain (update). */
    GL_ERR_CRC = -3,        /**< Gain set checksum does not match its payload. */
    GL_ERR_DIMS = -4,       /**< Gain set dimensions/structure/signature differ from the compiled ones. */
    GL_ERR_RANGE = -5,      /**< A value is out of its range (u_min > u_max, Ts <= 0, watchdog 0, a shift > 62). */
    GL_ERR_WATCHDOG = -6,   /**< No measurement for the configured number of periods: safe command. */
    GL_ERR_BUSY = -7,       /**< A staged gain set is still waiting to be applied. */
    GL_ERR_FPU = -8         /**< Startup self-test: the FPU is not enabled (Cortex-M port). */
} gl_status_t;

#ifdef __cplusplus
}
#endif

#endif /* GAINLINK_GL_STATUS_H */
