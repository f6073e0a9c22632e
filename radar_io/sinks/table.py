"""Table outputs of measurements: one writer per file format, all behind :class:`TableWriter`.

Every format gets the same columns in the same order (the decode order) and the
same file metadata (:func:`~radar_io.sinks.arrow_convert.output_metadata`). A file is
written under a temporary name beside the target and renamed when
:meth:`TableWriter.close` finishes it (:class:`~radar_io.sinks.atomic.AtomicFile`), so
an interrupted decode never leaves a file that looks complete. Writers stream:
memory holds one batch (Parquet: one row group of at most
:attr:`~radar_io.sinks.table_parquet.ParquetTableWriter.ROW_GROUP_ROWS` rows).

The formats and the file extensions that select them are registered in
:data:`radar_io.sinks.TABLE_FORMATS` and :data:`radar_io.sinks.TABLE_EXTENSIONS`.
"""

from __future__ import annotations

import errno
import os
import sys
from collections.abc import Mapping
from typing import IO, Any

import numpy as np

from radar_io.errors import ConfigError, StorageError
from radar_io.sinks.base import Batch, Sink


class TableWriter(Sink):
    """Streams measurement batches into one table file (``"-"``: standard output).

    ``open()`` creates the temporary file, ``write(batch)`` appends rows (returns the
    row count), ``close()`` finishes and renames it, ``abort()`` drops it. Used as a
    context manager, an exception aborts.
    """

    #: format name (``csv``, ``jsonl``, ``parquet``, ``arrow``)
    format: str = ""
    #: False for formats that can be written to a pipe
    needs_file: bool = False
    reopen = False

    def __init__(self, target: str | os.PathLike[str], *,
                 metadata: Mapping[str, str] | None = None) -> None:
        super().__init__(os.fspath(target))
        if self.target == "-" and self.needs_file:
            raise ConfigError(f"{self.format} output needs a file (-o OUT.{self.format})")
        self.metadata = dict(metadata or {})
        #: metadata known only at the end (framer counters), stored by formats with a footer
        self.final_metadata: dict[str, str] = {}
        self.rows = 0
        self._atomic: Any = None
        self._out: IO[bytes] | None = None
        self._started = False
        self._closed = False

    # -- Sink interface -------------------------------------------------------------------
    def open(self) -> None:
        if self.target == "-":
            self._out = sys.stdout.buffer
        else:
            import pyarrow as pa

            from radar_io.sinks.atomic import AtomicFile

            self._atomic = AtomicFile(self.target)
            # a native stream: the writers' many small writes never go through Python
            self._out = pa.BufferedOutputStream(pa.OSFile(str(self._atomic.tmp_path), "wb"),
                                                buffer_size=1 << 20)

    def write(self, batch: Batch) -> int:
        if self._out is None:
            self.open()
        try:
            if not self._started:
                self._start(batch)
                self._started = True
            n = len(batch[next(iter(_columns(batch)))]) if _columns(batch) else 0
            if n:
                self._write(batch)
        except OSError as exc:
            if _broken_pipe(exc):
                raise BrokenPipeError(str(exc)) from exc  # reader gone (`| head`): caller stops
            raise StorageError(f"cannot write {self.target}: {exc.strerror or exc}") from exc
        self.rows += n
        return n

    def close(self) -> None:
        """Finish the file and give it its final name (raises StorageError if the disk fails)."""
        if self._closed:
            return
        if self._out is None:
            self.open()
        try:
            if not self._started:
                self._start(_empty_batch())
                self._started = True
            self._finish()
            if self._atomic is not None:
                assert self._out is not None
                self._out.close()
                self._atomic.commit()
            else:
                assert self._out is not None
                self._out.flush()
        except OSError as exc:
            self.abort()
            if _broken_pipe(exc):
                raise BrokenPipeError(str(exc)) from exc
            raise StorageError(f"cannot write {self.target}: {exc.strerror or exc}") from exc
        except BaseException:
            self.abort()
            raise
        self._closed = True

    def abort(self) -> None:
        """Drop the unfinished file (nothing appears under the target name); never raises."""
        self._closed = True
        if self._atomic is not None:
            try:
                if self._out is not None:
                    self._out.close()
            except Exception:  # noqa: BLE001 - dropping the file anyway
                pass
            self._atomic.abort()

    def stats(self) -> dict[str, Any]:
        return {"rows": self.rows, "format": self.format}

    # -- per format -----------------------------------------------------------------------
    def _start(self, batch: Batch) -> None:
        """Write the header (schema, column names) from the first batch."""

    def _write(self, batch: Batch) -> None:
        raise NotImplementedError

    def _finish(self) -> None:
        """Write the trailer (footer); the file is then complete."""


def _broken_pipe(exc: OSError) -> bool:
    """True for a write to a pipe whose reader has gone (pyarrow reports it without errno)."""
    return isinstance(exc, BrokenPipeError) or exc.errno == errno.EPIPE \
        or "Broken pipe" in str(exc)


def _columns(batch: Batch) -> tuple[str, ...]:
    return tuple(getattr(batch, "columns", None) or batch.keys())


def _empty_batch() -> Any:
    """A zero-row batch with the default decoder's columns (a file with no frames)."""
    from radar_io.decoding.batch_decoder import BatchDecoder

    dec = BatchDecoder()
    return dec.batch(np.empty((0, dec.spec.length // 2), np.uint16), {})

