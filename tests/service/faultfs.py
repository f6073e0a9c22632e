"""Fault injection for a service in a child process, loaded by a ``sitecustomize.py``
(:func:`shim`) when ``RADAR_FAULTFS_FLAGS`` and ``RADAR_FAULTFS_DIR`` are set.

Real files, real service; only the OS calls on files under ``RADAR_FAULTFS_DIR`` (the
recordings directory) are patched, through flag files in ``RADAR_FAULTFS_FLAGS``. While
``FLAGDIR/full`` exists, ``os.write`` to such a file writes half of what it was given and
raises ENOSPC, as a filling disk does (new files can still be created: a full disk usually
has inodes left); while ``FLAGDIR/fsync`` exists, ``os.fsync`` raises EIO. Used by
test_storage_faults.py (no tiny tmpfs can be mounted in the test environment).
"""

from __future__ import annotations

import errno
import os


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


def install_from_env() -> None:
    flags, rec_dir = os.environ.get("RADAR_FAULTFS_FLAGS"), os.environ.get("RADAR_FAULTFS_DIR")
    if flags and rec_dir:
        install(os.path.abspath(flags), os.path.abspath(rec_dir))


def shim(directory: str) -> str:
    """Write a ``sitecustomize.py`` into ``directory`` that installs the faults at start;
    returns a PYTHONPATH with it first."""
    here = os.path.dirname(os.path.abspath(__file__))
    with open(os.path.join(directory, "sitecustomize.py"), "w", encoding="utf-8") as f:
        f.write(f"import sys\nsys.path.insert(0, {here!r})\nimport faultfs\n"
                "faultfs.install_from_env()\n")
    return os.pathsep.join([directory] + [p for p in os.environ.get("PYTHONPATH", "").split(
        os.pathsep) if p])
