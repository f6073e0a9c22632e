"""Parquet (zstd) through pyarrow's ParquetWriter, row group by row group.

Batches are gathered until :attr:`ParquetTableWriter.ROW_GROUP_ROWS` rows (at most
1 M) and written as one row group, so memory holds one row group of columns. The
schema carries the units (field metadata ``unit``) and the file metadata
(``radar_io.spec_version``, ``radar_io.site``, ``radar_io.calibration_id``,
``radar_io.source_file``, ``radar_io.source_sha256`` …); the writer's ``final_metadata``
(framer counters such as ``radar_io.crc_errors``) goes into the file footer's key-value
metadata, read by ``pq.read_metadata(f).metadata`` or DuckDB's ``parquet_kv_metadata``.
"""

from __future__ import annotations

from typing import Any

from radar_io.sinks.base import Batch
from radar_io.sinks.table import TableWriter


class ParquetTableWriter(TableWriter):
    format = "parquet"
    needs_file = True
    #: rows per row group (≤ 1 M; 256 Ki rows of ~20 columns ≈ 35 MB held)
    ROW_GROUP_ROWS = 1 << 18
    COMPRESSION = "zstd"

    def _start(self, batch: Batch) -> None:
        import pyarrow.parquet as pq

        from radar_io.sinks.arrow_convert import batch_to_arrow

        self._schema = batch_to_arrow(batch, self.metadata).schema
        import pyarrow as pa

        # dictionary encoding only where values repeat (flags, counters); measured floats
        # are nearly all distinct, and a dictionary attempt costs time and buffered pages
        small = [f.name for f in self._schema if not pa.types.is_floating(f.type)]
        self._writer: Any = pq.ParquetWriter(self._out, self._schema,
                                             compression=self.COMPRESSION,
                                             use_dictionary=small)
        self._pending: list[Any] = []
        self._pending_rows = 0

    def _write(self, batch: Batch) -> None:
        from radar_io.sinks.arrow_convert import batch_to_arrow

        rb = batch_to_arrow(batch, schema=self._schema)
        self._pending.append(rb)
        self._pending_rows += rb.num_rows
        while self._pending_rows >= self.ROW_GROUP_ROWS:
            self._flush(self.ROW_GROUP_ROWS)

    def _flush(self, rows: int) -> None:
        """Write the first ``rows`` pending rows as one row group."""
        import pyarrow as pa

        table = pa.Table.from_batches(self._pending, self._schema)
        self._writer.write_table(table.slice(0, rows), row_group_size=rows)
        rest = table.slice(rows)
        self._pending = rest.to_batches() if rest.num_rows else []
        self._pending_rows = rest.num_rows

    def _finish(self) -> None:
        if self._pending_rows:
            self._flush(self._pending_rows)
        elif not self.rows:
            import pyarrow as pa

            self._writer.write_table(pa.Table.from_batches([], self._schema))
        if self.final_metadata:  # file key-value metadata, in the footer
            from radar_io.sinks.arrow_convert import META_PREFIX

            self._writer.add_key_value_metadata(
                {f"{META_PREFIX}{k}": str(v) for k, v in self.final_metadata.items()})
        self._writer.close()
