/**
 * @file gl_log.h
 * @brief Event lines of the host apps: rate-limited, and never blocking the loop.
 *
 * A hostile peer can cause an event per datagram (a refused commit, a malformed frame), hundreds of
 * thousands a second; one stderr line each stalls the loop as soon as whoever reads stderr falls behind
 * (a pipe holds 64 KiB). So:
 * - at most `burst` lines are written per one-second window; the rest are counted, and the next window
 *   that writes anything (or gl_log_tick()) first writes one summary line
 *   `PREFIX: N more events not shown in the last S s (rate limit B/s)`;
 * - a line is written only when the descriptor can take it at once (poll() for POLLOUT with a zero
 *   timeout, then a single write() of less than PIPE_BUF bytes, which a pipe takes whole or not at all);
 *   otherwise it is dropped and counted in gl_log_t::dropped.
 * Every event is counted whether or not its line was written.
 */
#ifndef GAINLINK_GL_LOG_H
#define GAINLINK_GL_LOG_H

#include <stdint.h>

/** Lines per second written by default. */
#define GL_LOG_BURST_DEFAULT 20u

/** Longest line (shorter than PIPE_BUF, so a pipe write is atomic). */
#define GL_LOG_LINE_MAX 512u

/** An event log on one descriptor. */
typedef struct gl_log {
    int fd;                  /**< Descriptor lines go to (2: stderr). */
    const char *prefix;      /**< Start of every line, e.g. "gainlink_can". */
    uint32_t burst;          /**< Lines per window. */
    uint64_t window_start;   /**< Start of the current window (CLOCK_MONOTONIC ns). */
    uint32_t in_window;      /**< Lines written in the current window. */
    uint64_t held;           /**< Events not shown since the last summary line. */
    uint64_t held_since;     /**< When the first of them happened (ns). */
    uint64_t events;         /**< Every event logged. */
    uint64_t written;        /**< Lines written (summaries included). */
    uint64_t suppressed;     /**< Events not shown because of the rate limit. */
    uint64_t dropped;        /**< Lines dropped because the descriptor could not take them at once. */
} gl_log_t;

/**
 * @brief Set up a log.
 * @param[out] log     Log.
 * @param[in]  fd      Descriptor (2 for stderr).
 * @param[in]  prefix  Line prefix (kept, not copied).
 * @param[in]  burst   Lines per second (>= 1).
 */
void gl_log_init(gl_log_t *log, int fd, const char *prefix, uint32_t burst);

/**
 * @brief Log one event: count it, and write `PREFIX: <message>` if the rate limit and the descriptor allow.
 * @param[in,out] log  Log.
 * @param[in]     fmt  printf format of the message, then its arguments.
 */
void gl_log_event(gl_log_t *log, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/**
 * @brief Write a line now, bypassing the rate limit (start-up, the exit summary); still never blocks.
 * @param[in,out] log  Log.
 * @param[in]     fmt  printf format, then its arguments.
 */
void gl_log_always(gl_log_t *log, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/**
 * @brief Call from the loop now and then (e.g. every wake-up): writes the summary of a window that has ended.
 * @param[in,out] log  Log.
 */
void gl_log_tick(gl_log_t *log);

#endif /* GAINLINK_GL_LOG_H */
