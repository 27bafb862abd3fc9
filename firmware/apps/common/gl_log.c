/**
 * @file gl_log.c
 * @brief Rate-limited, non-blocking event lines (see gl_log.h).
 */
#define _POSIX_C_SOURCE 200809L
#include "gl_log.h"

#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <time.h>
#include <unistd.h>

#define WINDOW_NS 1000000000ull

static uint64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

/* One write() if the descriptor can take the line at once; else count it dropped. */
static void emit(gl_log_t *log, const char *line, size_t len)
{
    struct pollfd pfd = {.fd = log->fd, .events = POLLOUT, .revents = 0};
    if (poll(&pfd, 1, 0) == 1 && (pfd.revents & POLLOUT) && write(log->fd, line, len) == (ssize_t)len) {
        log->written++;
    } else {
        log->dropped++;
    }
}

static void emit_fmt(gl_log_t *log, const char *fmt, va_list ap)
{
    char line[GL_LOG_LINE_MAX];
    int head = snprintf(line, sizeof line, "%s: ", log->prefix);
    if (head < 0 || (size_t)head >= sizeof line - 1u) {
        return;
    }
    int body = vsnprintf(&line[head], sizeof line - (size_t)head - 1u, fmt, ap);
    if (body < 0) {
        return;
    }
    size_t len = (size_t)head + ((size_t)body < sizeof line - (size_t)head - 1u ? (size_t)body
                                                                                  : sizeof line - (size_t)head - 2u);
    line[len++] = '\n';
    emit(log, line, len);
}

static void summarise(gl_log_t *log, uint64_t now)
{
    if (log->held == 0u) {
        return;
    }
    char line[GL_LOG_LINE_MAX];
    int len = snprintf(line, sizeof line, "%s: %llu more events not shown in the last %.1f s (rate limit %u/s)\n",
                       log->prefix, (unsigned long long)log->held, (double)(now - log->held_since) * 1e-9,
                       (unsigned)log->burst);
    if (len > 0 && (size_t)len < sizeof line) {
        emit(log, line, (size_t)len);
    }
    log->held = 0u;
}

void gl_log_init(gl_log_t *log, int fd, const char *prefix, uint32_t burst)
{
    *log = (gl_log_t){.fd = fd, .prefix = prefix, .burst = burst > 0u ? burst : 1u, .window_start = now_ns()};
}

void gl_log_tick(gl_log_t *log)
{
    uint64_t now = now_ns();
    if (now - log->window_start >= WINDOW_NS) {
        summarise(log, now);
        log->window_start = now;
        log->in_window = 0u;
    }
}

void gl_log_event(gl_log_t *log, const char *fmt, ...)
{
    log->events++;
    gl_log_tick(log);
    if (log->in_window >= log->burst) {
        if (log->held == 0u) {
            log->held_since = now_ns();
        }
        log->held++;
        log->suppressed++;
        return;
    }
    log->in_window++;
    va_list ap;
    va_start(ap, fmt);
    emit_fmt(log, fmt, ap);
    va_end(ap);
}

void gl_log_always(gl_log_t *log, const char *fmt, ...)
{
    summarise(log, now_ns());
    va_list ap;
    va_start(ap, fmt);
    emit_fmt(log, fmt, ap);
    va_end(ap);
}
