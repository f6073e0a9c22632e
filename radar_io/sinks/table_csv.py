"""CSV through pyarrow's streaming CSV writer.

Header line of the column names (unquoted), one row per frame; an empty field is
"no value" (an NG sample's compensated and coordinate columns). Floats are printed
in their shortest round-trip form (``1`` for 1.0), so reading them back gives the
decoder's float64 to the last bit.
"""

from __future__ import annotations

from typing import Any

from radar_io.sinks.base import Batch
from radar_io.sinks.table import TableWriter


class CsvTableWriter(TableWriter):
    format = "csv"

    def _start(self, batch: Batch) -> None:
        import pyarrow.csv as pcsv

        from radar_io.sinks.arrow_convert import batch_to_arrow

        rb = batch_to_arrow(batch, self.metadata)
        self._schema = rb.schema
        opts = pcsv.WriteOptions(include_header=True, quoting_header="none",
                                 quoting_style="needed", batch_size=8192)
        self._writer: Any = pcsv.CSVWriter(self._out, rb.schema, write_options=opts)

    def _write(self, batch: Batch) -> None:
        from radar_io.sinks.arrow_convert import batch_to_arrow

        self._writer.write_batch(batch_to_arrow(batch, schema=self._schema))

    def _finish(self) -> None:
        self._writer.close()
