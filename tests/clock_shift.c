/**
 * @file clock_shift.c
 * @brief Test helper, an LD_PRELOAD library: moves a process's CLOCK_MONOTONIC forward on request.
 *
 * clock_gettime(CLOCK_MONOTONIC) returns the real clock plus a shift in microseconds that the test writes, as
 * a native int64, into the 8-byte file named by GL_CLOCK_SHIFT_FILE (mapped once, read on every call). Every
 * other clock, and every call when the variable is unset, goes to the C library untouched. The shift only
 * grows, so the clock stays monotonic. It lets a test take the firmware app's clock a minute ahead (the persist
 * rate limit's refill) without waiting a minute, and without any test hook in the firmware itself.
 *
 * Built by tests/test_mavlink_signing.py with `cc -shared -fPIC`; used only by the tests.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <fcntl.h>
#include <stdint.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

typedef int (*clock_gettime_fn)(clockid_t, struct timespec *);

static clock_gettime_fn real_clock_gettime;
static const int64_t *shift_us;

__attribute__((constructor)) static void clock_shift_init(void)
{
    real_clock_gettime = (clock_gettime_fn)dlsym(RTLD_NEXT, "clock_gettime");
    const char *path = getenv("GL_CLOCK_SHIFT_FILE");
    if (path == NULL) {
        return;
    }
    int fd = open(path, O_RDONLY);
    if (fd < 0) {
        return;
    }
    void *p = mmap(NULL, sizeof(int64_t), PROT_READ, MAP_SHARED, fd, 0);
    close(fd);
    if (p != MAP_FAILED) {
        shift_us = p;
    }
}

int clock_gettime(clockid_t id, struct timespec *ts)
{
    if (real_clock_gettime == NULL) {
        real_clock_gettime = (clock_gettime_fn)dlsym(RTLD_NEXT, "clock_gettime");
    }
    int rc = real_clock_gettime(id, ts);
    if (rc == 0 && id == CLOCK_MONOTONIC && shift_us != NULL) {
        int64_t us = __atomic_load_n(shift_us, __ATOMIC_RELAXED);
        if (us > 0) {
            int64_t ns = (int64_t)ts->tv_nsec + (us % 1000000) * 1000;
            ts->tv_sec += (time_t)(us / 1000000 + ns / 1000000000);
            ts->tv_nsec = (long)(ns % 1000000000);
        }
    }
    return rc;
}
