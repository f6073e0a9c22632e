/* Preloaded before libfaketime: monotonic sleeps and waits go straight to the kernel / libc.
 *
 * libfaketime 0.9.10 with FAKETIME_DONT_FAKE_MONOTONIC=1 fails clock_nanosleep on
 * CLOCK_MONOTONIC with EINVAL (libfaketime issue 426), which breaks Python's time.sleep,
 * and shifts the deadline of a timed wait on a CLOCK_MONOTONIC condition variable by the
 * fake offset: CPython's GIL hand-over waits on one, so after a step a thread could wait
 * seconds for the GIL. The monotonic clock is not faked anyway, so these need no faking:
 * this shim makes the system call, or calls libc's own pthread_cond_timedwait, itself and
 * hands everything on other clocks to the next library (libfaketime).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <pthread.h>
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

typedef int (*cond_wait_fn)(pthread_cond_t *, pthread_mutex_t *, const struct timespec *);

int pthread_cond_timedwait(pthread_cond_t *cond, pthread_mutex_t *mutex,
                           const struct timespec *abstime)
{
    static cond_wait_fn libc_wait, next;
    if (libc_wait == NULL) {
        void *libc = dlopen("libc.so.6", RTLD_NOW | RTLD_NOLOAD);
        libc_wait = (cond_wait_fn)dlvsym(libc, "pthread_cond_timedwait", "GLIBC_2.3.2");
        next = (cond_wait_fn)dlvsym(RTLD_NEXT, "pthread_cond_timedwait", "GLIBC_2.3.2");
    }
    /* glibc keeps the condition variable's clock in bit 1 of __wrefs (1: CLOCK_MONOTONIC) */
    if ((cond->__data.__wrefs >> 1) & 1)
        return libc_wait(cond, mutex, abstime);
    return next(cond, mutex, abstime);
}
