"""ASTERIX CAT048 target reports as sinks.

* :class:`AsterixSink` — live: one data block per UDP datagram (``udp://HOST:PORT``), or
  concatenated blocks on a serial link / in a file (reopened with back-off by SinkWorker).
* :class:`AsterixFileWriter` — batch (``radar-io decode INPUT -o OUT.ast``): concatenated
  data blocks written under a temporary name and renamed on ``close()``; ``abort()``
  leaves nothing under the target name. Same face as the table writers
  (``target, *, metadata``; write / close / abort).
"""

from __future__ import annotations

import os
import sys
from typing import IO, Any

from radar_io.encoding.asterix_cat048 import Cat048Encoder
from radar_io.errors import StorageError
from radar_io.sinks.atomic import AtomicFile
from radar_io.sinks.base import Batch, EncoderSink, Sink


class AsterixSink(EncoderSink):
    """CAT048 records of measurement batches (see :mod:`radar_io.encoding.asterix_cat048`).

    ``encoder`` carries SAC/SIC (default 0/0); or give ``sac``/``sic`` (or a ``site``).
    """

    def __init__(self, target: str, encoder: Cat048Encoder | None = None, *,
                 sac: int | None = None, sic: int | None = None, site: Any = None,
                 **options: Any) -> None:
        if encoder is None:
            if site is not None:
                encoder = Cat048Encoder.for_site(site, **options)
            else:
                encoder = Cat048Encoder(sac or 0, sic or 0, **options)
        super().__init__(target, encoder, 0)  # 0: one datagram per write (per block)
        self.encoder: Cat048Encoder = encoder

    def write(self, batch: Batch) -> int:
        n = 0
        for block in self.encoder.encode_blocks(batch):
            self.link.write(block)
            n += len(block)
        return n

    def stats(self) -> dict[str, Any]:
        enc = self.encoder
        return {"records": enc.records, "blocks": enc.blocks, "saturation": dict(enc.saturation),
                "bytes": self.link.bytes, "sac": enc.sac, "sic": enc.sic}


class AsterixFileWriter(Sink):
    """Concatenated CAT048 data blocks in one file (``"-"``: standard output), complete only
    after :meth:`close`. ``site`` gives SAC/SIC (``[asterix] sac, sic``); ``metadata`` (the
    table writers' file metadata) has no place in ASTERIX and is ignored."""

    format = "ast"
    reopen = False

    def __init__(self, target: str | os.PathLike[str], *, metadata: Any = None,
                 site: Any = None, encoder: Cat048Encoder | None = None,
                 **options: Any) -> None:
        super().__init__(os.fspath(target))
        self.encoder = encoder or (Cat048Encoder.for_site(site, **options) if site is not None
                                   else Cat048Encoder(**options))
        self._out: IO[bytes] | None = None
        self._atomic: AtomicFile | None = None
        self.bytes = 0
        #: what decode adds at the end for the table formats; ASTERIX has no place for it
        self.final_metadata: dict[str, str] = {}

    def open(self) -> None:
        if self._out is not None:
            return
        if self.target == "-":
            self._out = sys.stdout.buffer
            return
        self._atomic = AtomicFile(self.target)  # the table writers' temporary-name file
        self._out = open(self._atomic.tmp_path, "wb", buffering=1 << 20)  # noqa: SIM115 - until close()

    def write(self, batch: Batch) -> int:
        if self._out is None:
            self.open()
        data = self.encoder.encode_batch(batch)
        try:
            self._out.write(data)  # type: ignore[union-attr]
        except OSError as exc:
            raise StorageError(f"cannot write {self.target}: {exc.strerror}",
                               errno=exc.errno) from exc
        self.bytes += len(data)
        return len(data)

    def close(self) -> None:
        """Flush and give the file its name (StorageError if the disk fails)."""
        out, self._out = self._out, None
        atomic, self._atomic = self._atomic, None
        if out is None:
            return
        if atomic is None:  # stdout
            out.flush()
            return
        try:
            out.close()
        except OSError as exc:
            atomic.abort()
            raise StorageError(f"cannot write {self.target}: {exc.strerror}",
                               errno=exc.errno) from exc
        atomic.commit()

    def abort(self) -> None:
        """Drop the unfinished file; never raises."""
        out, self._out = self._out, None
        atomic, self._atomic = self._atomic, None
        if out is not None and atomic is not None:
            try:
                out.close()
            except OSError:
                pass
        if atomic is not None:
            atomic.abort()

    def stats(self) -> dict[str, Any]:
        enc = self.encoder
        return {"records": enc.records, "blocks": enc.blocks, "bytes": self.bytes,
                "saturation": dict(enc.saturation), "format": self.format}


def service_sink(svc: Any, target: str) -> AsterixSink:
    """What ``serve --asterix-out URL`` opens: SAC/SIC from the service's site, SIM set when
    the data is not live (the simulator, or ``--source replay://`` driving the outputs from
    a recording). Run it in a :class:`~radar_io.sinks.worker.SinkWorker` fed by the live
    pipeline's processors."""
    from radar_io.sources import source_kind

    simulated = source_kind(str(svc.cfg.source)) in ("sim", "replay")
    if svc.site is not None:
        return AsterixSink(target, site=svc.site, simulated=simulated)
    return AsterixSink(target, simulated=simulated)
