"""radar_io: ground tracking radar and airborne recorder interface for flight test.

``import radar_io`` is cheap: the public names below are loaded on first use (PEP 562),
so FastAPI, OpenCV, cantools and pyproj are imported only by the parts that need them.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

#: public name → module that defines it
_LAZY: dict[str, str] = {
    "Calibration": "radar_io.decoding.biases",
    "load_calibration": "radar_io.decoding.biases",
    "save_calibration": "radar_io.decoding.biases",
    "MeasurementBatch": "radar_io.decoding.measurement",
    "decode_bytes": "radar_io.decoding.batch_decoder",
    "iter_decode": "radar_io.decoding.batch_decoder",
    "open_source": "radar_io.sources",
    "open_sink": "radar_io.sinks",
}
_ERRORS = ("RadarIOError", "ValidationError", "ConfigError", "SpecError", "FrameError",
           "EncodeError", "RecordingError", "NotFoundError", "ConflictError", "UnavailableError",
           "SourceError", "UplinkError", "StorageError")
_LAZY.update(dict.fromkeys(_ERRORS, "radar_io.errors"))

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs; `X as X` re-exports
    from radar_io.decoding.batch_decoder import decode_bytes as decode_bytes
    from radar_io.decoding.batch_decoder import iter_decode as iter_decode
    from radar_io.decoding.biases import Calibration as Calibration
    from radar_io.decoding.biases import load_calibration as load_calibration
    from radar_io.decoding.biases import save_calibration as save_calibration
    from radar_io.decoding.measurement import MeasurementBatch as MeasurementBatch
    from radar_io.errors import *  # noqa: F403
    from radar_io.sinks import open_sink as open_sink
    from radar_io.sources import open_source as open_source


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'radar_io' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_LAZY])


__all__ = ["__version__", *_LAZY]  # noqa: PLE0604 - the keys of _LAZY are names
