"""Arrow IPC file format (``.arrow``, also read as Feather v2), one record batch per decode batch.

Uncompressed, so a reader can memory-map it; the schema carries the units and the
file metadata, as in Parquet.
"""

from __future__ import annotations

from typing import Any

from radar_io.sinks.base import Batch
from radar_io.sinks.table import TableWriter


class ArrowTableWriter(TableWriter):
    format = "arrow"
    needs_file = True

    def _start(self, batch: Batch) -> None:
        import pyarrow as pa

        from radar_io.sinks.arrow_convert import batch_to_arrow

        self._schema = batch_to_arrow(batch, self.metadata).schema
        self._writer: Any = pa.ipc.new_file(self._out, self._schema)

    def _write(self, batch: Batch) -> None:
        from radar_io.sinks.arrow_convert import batch_to_arrow

        self._writer.write_batch(batch_to_arrow(batch, schema=self._schema))

    def _finish(self) -> None:
        self._writer.close()
