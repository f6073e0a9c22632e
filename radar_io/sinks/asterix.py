"""ASTERIX CAT048 target reports as a sink: one data block per UDP datagram
(``udp://HOST:PORT``), or concatenated blocks in a file / on a serial link."""

from __future__ import annotations

from typing import Any

from radar_io.encoding.asterix_cat048 import Cat048Encoder
from radar_io.sinks.base import Batch, EncoderSink


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
