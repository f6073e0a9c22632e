"""Atomic output files: written under a temporary name, renamed only when complete.

:class:`AtomicFile` creates ``.NAME.XXXXXX.part`` in the target's directory (same file
system, so the final :func:`os.replace` is atomic). :meth:`AtomicFile.commit` flushes,
fsyncs and renames; :meth:`AtomicFile.abort` deletes the temporary file. A process
killed outright (SIGKILL, power loss) leaves at most the hidden ``.part`` file, never a
file under the final name that looks complete.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from radar_io.errors import ConfigError, StorageError

#: suffix of the temporary files (``radar-io`` never reads them)
PART_SUFFIX = ".part"


class AtomicFile:
    """A file that appears under ``path`` only after :meth:`commit`.

    The temporary file is created empty at :attr:`tmp_path`; the caller writes it (any
    way: a native Arrow stream, a Python file) and closes its handle before ``commit``.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        directory = self.path.parent
        try:
            fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=PART_SUFFIX,
                                       dir=directory)
        except FileNotFoundError as exc:
            raise ConfigError(f"cannot write {self.path}: directory {directory} does not exist") \
                from exc
        except OSError as exc:
            raise ConfigError(f"cannot write {self.path}: {exc.strerror}") from exc
        os.fchmod(fd, 0o644)
        os.close(fd)
        self.tmp_path = Path(tmp)
        self.done = False

    def commit(self) -> None:
        """Flush, fsync and rename to the final name (atomic replace of any old file)."""
        if self.done:
            return
        try:
            fd = os.open(self.tmp_path, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(self.tmp_path, self.path)
        except OSError as exc:
            self.abort()
            raise StorageError(f"cannot write {self.path}: {exc.strerror}") from exc
        self.done = True
        try:  # make the rename itself durable
            dfd = os.open(self.path.parent, os.O_RDONLY)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)
        except OSError:
            pass

    def abort(self) -> None:
        """Drop the temporary file; never raises."""
        if self.done:
            return
        self.done = True
        try:
            os.unlink(self.tmp_path)
        except OSError:
            pass

    def __enter__(self) -> AtomicFile:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.abort()


class AtomicStream:
    """A buffered binary file written under a temporary name: :meth:`write`, then
    :meth:`close` (flush, fsync, rename) or :meth:`abort` (delete). Disk trouble is a
    StorageError naming the file."""

    def __init__(self, path: str | os.PathLike[str], buffering: int = 1 << 20) -> None:
        self.atomic = AtomicFile(path)
        self.path = self.atomic.path
        self._f = open(self.atomic.tmp_path, "wb", buffering=buffering)  # noqa: SIM115

    def write(self, data: bytes) -> None:
        try:
            self._f.write(data)
        except OSError as exc:
            raise StorageError(f"cannot write {self.path}: {exc.strerror}",
                               errno=exc.errno) from exc

    def close(self) -> None:
        """Flush and give the file its name."""
        try:
            self._f.close()
        except OSError as exc:
            self.abort()
            raise StorageError(f"cannot write {self.path}: {exc.strerror}",
                               errno=exc.errno) from exc
        self.atomic.commit()

    def abort(self) -> None:
        """Drop the unfinished file; never raises."""
        try:
            self._f.close()
        except OSError:
            pass
        self.atomic.abort()
