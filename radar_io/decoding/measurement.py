"""``MeasurementBatch``: decoded measurements as numpy columns plus the framer counters."""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from typing import Any, Protocol

import numpy as np


class Columns(Protocol):
    """Equal-length columns by name (units in the names), read-only: a dict of arrays or a
    :class:`MeasurementBatch` (which is not a Mapping: its ``len`` counts rows)."""

    def __getitem__(self, name: str, /) -> np.ndarray: ...
    def __contains__(self, name: object, /) -> bool: ...
    def keys(self) -> Iterable[str]: ...


class MeasurementBatch:
    """Decoded measurements as numpy columns: ``batch["sr_m"]``; ``batch.stats`` holds the framer counters."""

    def __init__(self, columns: dict[str, np.ndarray], stats: dict[str, int] | None = None,
                 order: Iterable[str] | None = None) -> None:
        self._cols = columns
        self.columns: tuple[str, ...] = tuple(order) if order is not None else tuple(columns)
        self.stats: dict[str, int] = dict(stats or {})

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self._cols[name]
        except KeyError as exc:
            raise KeyError(f"no column {name!r}; columns are {', '.join(self.columns)}") from exc

    def __contains__(self, name: object) -> bool:
        return name in self._cols

    def __iter__(self) -> Iterator[str]:
        """The column names in decode order (``len`` counts rows, as for a table)."""
        return iter(self.columns)

    def __len__(self) -> int:
        return len(self._cols[self.columns[0]]) if self.columns else 0

    def keys(self) -> tuple[str, ...]:
        return self.columns

    def to_arrow(self, metadata: Mapping[str, str] | None = None) -> Any:
        """A :class:`pyarrow.RecordBatch` of the columns in decode order, zero-copy from numpy
        where the dtype allows; units in each field's metadata, NaN (no value) as null.
        ``metadata`` goes into the schema as ``radar_io.<key>``. Imports pyarrow."""
        from radar_io.sinks.arrow_convert import batch_to_arrow

        return batch_to_arrow(self, metadata)

    def __repr__(self) -> str:
        return f"MeasurementBatch({len(self)} rows, stats={self.stats})"

    @classmethod
    def concat(cls, batches: list[MeasurementBatch], stats: dict[str, int] | None = None
               ) -> MeasurementBatch:
        if not batches:
            raise ValueError("no batches to concatenate")
        order = batches[0].columns
        cols = {c: np.concatenate([b[c] for b in batches]) for c in order}
        return cls(cols, stats if stats is not None else batches[-1].stats, order)
