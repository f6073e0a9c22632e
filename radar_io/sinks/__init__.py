"""Sinks: where decoded measurements go, opened by kind (:data:`SINKS`).

:data:`SINKS` maps a sink kind to ``"module:class"``; the module is imported only when
that kind is opened. Every sink implements :class:`~radar_io.sinks.base.Sink`
(open, write a batch, close, reopen policy). A new sink is one module and one line here.
"""

from __future__ import annotations

import importlib
from typing import Any

from radar_io.errors import ValidationError
from radar_io.sinks.base import Batch, Sink

#: kind → "module:class(target, **options)"
SINKS: dict[str, str] = {
    "tlm1": "radar_io.sinks.uplink:TelemetrySink",
    "da": "radar_io.sinks.uplink:DASink",
    "asterix": "radar_io.sinks.asterix:AsterixSink",
    "mqtt": "radar_io.sinks.mqtt:MqttSink",
}


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


__all__ = ["Batch", "SINKS", "Sink", "open_sink", "sink_class"]
