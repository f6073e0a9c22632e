"""JSON lines: one object per frame, keys in the decode column order, ``null`` for no value.

Formatted column-wise by Arrow compute (numbers cast to their shortest round-trip
text, joined element-wise), so no Python loop over rows. JSON lines has no place
for file metadata: use Parquet or Arrow when the provenance must travel with the data.
"""

from __future__ import annotations

from typing import Any

from radar_io.sinks.base import Batch
from radar_io.sinks.table import TableWriter


class JsonlTableWriter(TableWriter):
    format = "jsonl"
    #: rows formatted at a time (bounds the memory of the text being built)
    ROWS_PER_WRITE = 65536

    def _start(self, batch: Batch) -> None:
        from radar_io.sinks.arrow_convert import batch_to_arrow

        self._schema = batch_to_arrow(batch, self.metadata).schema

    def _write(self, batch: Batch) -> None:
        import pyarrow as pa
        import pyarrow.compute as pc

        from radar_io.sinks.arrow_convert import batch_to_arrow

        rb = batch_to_arrow(batch, schema=self._schema)
        for s in range(0, rb.num_rows, self.ROWS_PER_WRITE):
            part = rb.slice(s, self.ROWS_PER_WRITE)
            texts: list[Any] = []
            for i, name in enumerate(part.schema.names):
                col = part.column(i)
                txt = pc.cast(col, pa.string())
                if pa.types.is_floating(col.type):  # NaN / inf are not JSON numbers
                    txt = pc.if_else(pc.is_finite(col), txt, pa.scalar(None, pa.string()))
                texts.append(pc.binary_join_element_wise(
                    f'"{name}":', pc.fill_null(txt, "null"), ""))
            line = pc.binary_join_element_wise("{", pc.binary_join_element_wise(*texts, ","),
                                               "}\n", "")
            # the values of a fresh string array lie back to back in its data buffer
            offsets = line.buffers()[1]
            first, last = (int(v) for v in
                           pa.Array.from_buffers(pa.int32(), len(line) + 1, [None, offsets],
                                                 offset=line.offset).to_numpy()[[0, -1]])
            self._out.write(memoryview(line.buffers()[2])[first:last])  # type: ignore[union-attr]
