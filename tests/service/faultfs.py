"""Fault injection for a service in a child process: ``python faultfs.py FLAGDIR serve …``.

Real files, real service; only the OS calls on files under ``FLAGDIR/../data/recordings``
are patched. While ``FLAGDIR/full`` exists, ``os.write`` to such a file writes half
of what it was given and raises ENOSPC, as a filling disk does (new files can still be
created: a full disk usually has inodes left); while ``FLAGDIR/fsync`` exists, ``os.fsync`` raises EIO. Used by
test_storage_faults.py (no tiny tmpfs can be mounted in the test environment).
"""

from __future__ import annotations

import errno
import os
import sys


def install(flag_dir: str, rec_dir: str) -> None:
    real_write, real_fsync = os.write, os.fsync
    full, fsync_fail = os.path.join(flag_dir, "full"), os.path.join(flag_dir, "fsync")

    def ours(fd: int) -> bool:
        try:
            return os.readlink(f"/proc/self/fd/{fd}").startswith(rec_dir)
        except OSError:
            return False

    def fwrite(fd, data):  # type: ignore[no-untyped-def]
        if os.path.exists(full) and ours(fd):
            n = len(data) // 2
            if n:  # half the chunk reaches the disk, then it is full
                real_write(fd, bytes(memoryview(data)[:n]))
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_write(fd, data)

    def ffsync(fd):  # type: ignore[no-untyped-def]
        if os.path.exists(fsync_fail) and ours(fd):
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real_fsync(fd)

    os.write, os.fsync = fwrite, ffsync


if __name__ == "__main__":
    flag_dir = os.path.abspath(sys.argv[1])
    argv = sys.argv[2:]
    data_dir = os.path.abspath(argv[argv.index("--data-dir") + 1])
    install(flag_dir, os.path.join(data_dir, "recordings"))
    from radar_io.cli.main import main

    sys.exit(main(argv))
