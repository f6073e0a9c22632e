/* Preloaded: fsync / fdatasync on files under $SLOWFS_DIR take $SLOWFS_DELAY_S seconds
 * longer, and each such call is logged to $SLOWFS_LOG as one line
 * "call tid thread-name monotonic-seconds path" (the thread name as the kernel knows it:
 * PR_GET_NAME; the time the call began on CLOCK_MONOTONIC).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

static int ours(int fd, char *path, size_t size)
{
    const char *dir = getenv("SLOWFS_DIR");
    char link[64];
    if (dir == NULL || *dir == 0)
        return 0;
    snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
    ssize_t n = readlink(link, path, size - 1);
    if (n < 0)
        return 0;
    path[n] = 0;
    return strncmp(path, dir, strlen(dir)) == 0;
}

static void slow_down(const char *call, int fd)
{
    char path[4096], name[17] = {0}, line[4300];
    if (!ours(fd, path, sizeof path))
        return;
    const char *log = getenv("SLOWFS_LOG");
    if (log != NULL) {
        struct timespec now;
        clock_gettime(CLOCK_MONOTONIC, &now);
        prctl(PR_GET_NAME, name, 0, 0, 0);
        int k = snprintf(line, sizeof line, "%s %ld %s %ld.%09ld %s\n", call,
                         (long)syscall(SYS_gettid), name, (long)now.tv_sec, now.tv_nsec, path);
        int lfd = open(log, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
        if (lfd >= 0) {
            if (write(lfd, line, (size_t)k) < 0) { /* the log is best effort */ }
            close(lfd);
        }
    }
    const char *d = getenv("SLOWFS_DELAY_S");
    double s = d != NULL ? atof(d) : 0.0;
    struct timespec ts = {(time_t)s, (long)((s - (double)(time_t)s) * 1e9)};
    while (nanosleep(&ts, &ts) == -1 && errno == EINTR) {
    }
}

int fsync(int fd)
{
    static int (*next)(int);
    if (next == NULL)
        next = (int (*)(int))dlsym(RTLD_NEXT, "fsync");
    slow_down("fsync", fd);
    return next(fd);
}

int fdatasync(int fd)
{
    static int (*next)(int);
    if (next == NULL)
        next = (int (*)(int))dlsym(RTLD_NEXT, "fdatasync");
    slow_down("fdatasync", fd);
    return next(fd);
}
