/* Preloaded before libfaketime: monotonic sleeps go straight to the kernel.
 *
 * libfaketime 0.9.10 with FAKETIME_DONT_FAKE_MONOTONIC=1 fails clock_nanosleep on
 * CLOCK_MONOTONIC with EINVAL (libfaketime issue 426), which breaks Python's time.sleep.
 * The monotonic clock is not faked anyway, so these sleeps need no faking: this shim
 * makes the system call itself and hands every other clock to the next library.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

int clock_nanosleep(clockid_t clock_id, int flags, const struct timespec *req,
                    struct timespec *rem)
{
    if (clock_id == CLOCK_MONOTONIC || clock_id == CLOCK_MONOTONIC_RAW ||
        clock_id == CLOCK_BOOTTIME) {
        long r = syscall(SYS_clock_nanosleep, clock_id, flags, req, rem);
        return r == 0 ? 0 : errno;  /* clock_nanosleep returns the error number */
    }
    static int (*next)(clockid_t, int, const struct timespec *, struct timespec *);
    if (next == NULL)
        next = (int (*)(clockid_t, int, const struct timespec *, struct timespec *))
            dlsym(RTLD_NEXT, "clock_nanosleep");
    return next(clock_id, flags, req, rem);
}

int nanosleep(const struct timespec *req, struct timespec *rem)
{
    /* a relative sleep: the same on every clock */
    return (int)syscall(SYS_nanosleep, req, rem);
}
