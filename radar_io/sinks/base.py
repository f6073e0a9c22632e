"""The sink interface: where decoded measurement batches go.

A :class:`Sink` is opened, written batch by batch, and closed. Its constructor only
checks the target (a malformed URL is refused at once, before anything starts);
:meth:`Sink.open` connects, and may fail while the far end is absent. A sink whose
``reopen`` is true is reopened by :class:`~radar_io.sinks.worker.SinkWorker` with the
sources' back-off (0.1 s doubling to 5 s) after a failed open or write.

Byte-oriented outputs (TLM1 frames, D/A words, ASTERIX blocks) are an *encoder* in
front of a :class:`~radar_io.sinks.base.ByteLink` (file, serial port, UDP):
:class:`EncoderSink`.
"""

from __future__ import annotations

import builtins
from abc import ABC, abstractmethod
from typing import Any, Protocol

from radar_io.decoding.measurement import Columns

#: a batch of measurements: column name → equal-length array (units in the names)
Batch = Columns


class Sink(ABC):
    """One output of measurement batches."""

    #: reopen after a failure (links to devices and peers); False for files
    reopen: bool = True

    def __init__(self, target: str) -> None:
        self.target = target

    @abstractmethod
    def open(self) -> None:
        """Connect or create the output; raises a RadarIOError subclass on failure."""

    @abstractmethod
    def write(self, batch: Batch) -> int:
        """Write one batch; returns the bytes (or records) written."""

    @abstractmethod
    def close(self) -> None:
        """Release the output; never raises."""

    def stats(self) -> dict[str, Any]:
        """Counters for ``/api/status`` (sink-specific)."""
        return {}

    # the old name of write(), kept for the uplink sinks' callers
    def send(self, batch: Batch) -> int:
        return self.write(batch)

    def __enter__(self) -> Sink:
        self.open()
        return self

    def abort(self) -> None:
        """Give up after an error: files drop what they wrote; by default the same as close()."""
        self.close()

    def __exit__(self, exc_type: object, *exc: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


class ByteLink(Protocol):
    """A byte destination (file, serial port, UDP socket) that writes whole records."""

    target: str
    kind: str
    handle: Any
    bytes: int  # written so far; shadows the type in this class body, hence builtins.bytes

    def open(self) -> None: ...
    def write(self, data: builtins.bytes) -> None: ...
    def close(self) -> None: ...


class Encoder(Protocol):
    """Turns a measurement batch into wire bytes (TLM1 frames, D/A words, ASTERIX)."""

    def encode_batch(self, batch: Batch) -> bytes: ...


class EncoderSink(Sink):
    """An encoder in front of a byte link: ``write(batch)`` encodes and writes it."""

    def __init__(self, target: str, encoder: Encoder, record_bytes: int) -> None:
        from radar_io.sinks.links import make_link

        super().__init__(target)
        self.encoder = encoder
        self.link: ByteLink = make_link(target, record_bytes)
        self.reopen = self.link.kind != "file"

    def open(self) -> None:
        self.link.open()

    def write(self, batch: Batch) -> int:
        data = self.encoder.encode_batch(batch)
        self.link.write(data)
        return len(data)

    def close(self) -> None:
        self.link.close()

    def stats(self) -> dict[str, Any]:
        enc: Any = self.encoder
        return {"records": getattr(enc, "frames", getattr(enc, "samples", 0)),
                "saturation": dict(getattr(enc, "saturation", {})), "bytes": self.link.bytes}
