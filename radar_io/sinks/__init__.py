"""Sinks: where decoded measurements go, opened by kind (:data:`SINKS`).

:data:`SINKS` maps a sink kind to ``"module:class"``; the module is imported only when
that kind is opened. Every sink implements :class:`~radar_io.sinks.base.Sink`
(open, write a batch, close, reopen policy). A new sink is one module and one line here.
"""

from __future__ import annotations

import importlib
import os
from typing import TYPE_CHECKING, Any, cast

from radar_io.errors import ValidationError
from radar_io.sinks.base import Batch, Sink

if TYPE_CHECKING:
    from radar_io.sinks.table import TableWriter

#: kind → "module:class(target, **options)"
SINKS: dict[str, str] = {
    "tlm1": "radar_io.sinks.uplink:TelemetrySink",
    "da": "radar_io.sinks.uplink:DASink",
    "asterix": "radar_io.sinks.asterix:AsterixSink",
    "mqtt": "radar_io.sinks.mqtt:MqttSink",
    "ast": "radar_io.sinks.asterix:AsterixFileWriter",   # decode -o OUT.ast (not a table)
    "ch10": "radar_io.sinks.ch10:Ch10Writer",  # IRIG 106 Chapter 10 from received chunks
}


#: table file format → "module:class(target, metadata=…)" (see :mod:`radar_io.sinks.table`)
TABLE_FORMATS: dict[str, str] = {
    "csv": "radar_io.sinks.table_csv:CsvTableWriter",
    "jsonl": "radar_io.sinks.table_jsonl:JsonlTableWriter",
    "parquet": "radar_io.sinks.table_parquet:ParquetTableWriter",
    "arrow": "radar_io.sinks.table_arrow:ArrowTableWriter",
}
#: file extension → table format
TABLE_EXTENSIONS: dict[str, str] = {
    ".csv": "csv", ".jsonl": "jsonl", ".ndjson": "jsonl", ".json": "jsonl",
    ".parquet": "parquet", ".pq": "parquet", ".arrow": "arrow", ".feather": "arrow",
    ".ipc": "arrow",
}
# each table format is also a sink kind (a file sink: written, finished on close)
SINKS.update(TABLE_FORMATS)


def table_format(target: str | None, fmt: str | None = None) -> str:
    """The table format: ``fmt`` if given, else from ``target``'s extension, else ``csv``."""
    if fmt:
        if fmt not in TABLE_FORMATS:
            raise ValidationError(f"unknown table format {fmt!r} "
                                  f"(known: {', '.join(TABLE_FORMATS)})")
        return fmt
    ext = os.path.splitext(target or "")[1].lower()
    return TABLE_EXTENSIONS.get(ext, "csv")


def open_table(target: str, fmt: str | None = None, **options: Any) -> TableWriter:
    """A table writer for ``target`` (``"-"``: stdout) in ``fmt`` or the extension's format,
    opened."""
    # every table format is registered as a TableWriter subclass
    return cast("TableWriter", open_sink(table_format(target, fmt), target, **options))


def sink_class(kind: str) -> type[Sink]:
    """The class registered for ``kind``; ValidationError names the known kinds."""
    try:
        module, _, name = SINKS[kind].partition(":")
    except KeyError as exc:
        raise ValidationError(f"unknown sink kind {kind!r} (known: {', '.join(sorted(SINKS))})") \
            from exc
    return getattr(importlib.import_module(module), name)


def open_sink(kind: str, target: str, **options: Any) -> Sink:
    """A sink of ``kind`` for ``target``, opened."""
    sink = sink_class(kind)(target, **options)
    sink.open()
    return sink


__all__ = [
    "SINKS",
    "TABLE_EXTENSIONS",
    "TABLE_FORMATS",
    "Batch",
    "Sink",
    "open_sink",
    "open_table",
    "sink_class",
    "table_format",
]
