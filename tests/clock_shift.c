/**
 * @file clock_shift.c
 * @brief Test helper, an LD_PRELOAD library: a process's CLOCK_MONOTONIC stands still and moves only on request.
 *
 * clock_gettime(CLOCK_MONOTONIC) returns the clock's reading when the library was loaded plus a shift in
 * microseconds that the test writes, as a native int64, into the 8-byte file named by GL_CLOCK_SHIFT_FILE (mapped
 * once, read on every call): between two writes the process sees no time pass, however long the test takes on a
 * loaded machine. Every other clock, and every call when the variable is unset, goes to the C library untouched.
 * The shift only grows, so the clock stays monotonic. It lets a test take the firmware app's clock a minute ahead
 * (the persist rate limit's refill) without waiting a minute, to the microsecond, and without any test hook in the
 * firmware itself.
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
static struct timespec frozen; /* CLOCK_MONOTONIC when the library was loaded */

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
    if (p != MAP_FAILED && real_clock_gettime(CLOCK_MONOTONIC, &frozen) == 0) {
        shift_us = p;
    }
}

int clock_gettime(clockid_t id, struct timespec *ts)
{
    if (real_clock_gettime == NULL) {
        real_clock_gettime = (clock_gettime_fn)dlsym(RTLD_NEXT, "clock_gettime");
    }
    if (id != CLOCK_MONOTONIC || shift_us == NULL) {
        return real_clock_gettime(id, ts);
    }
    int64_t us = __atomic_load_n(shift_us, __ATOMIC_RELAXED);
    us = us > 0 ? us : 0;
    int64_t ns = (int64_t)frozen.tv_nsec + (us % 1000000) * 1000;
    ts->tv_sec = frozen.tv_sec + (time_t)(us / 1000000 + ns / 1000000000);
    ts->tv_nsec = (long)(ns % 1000000000);
    return 0;
}
