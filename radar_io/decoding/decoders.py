"""Decoders: accepted frames → measurements (radar-interface.md §1, §2, §4, §5).

The old single module, kept so callers keep working; the code lives in

* :mod:`radar_io.decoding.model` — the one decode description (columns, compensation);
* :mod:`radar_io.decoding.frame_decoder` — :class:`FrameDecoder` (one frame, ``struct``);
* :mod:`radar_io.decoding.batch_decoder` — :class:`BatchDecoder`, :func:`decode_bytes`,
  :func:`iter_decode` (numpy, chunked);
* :mod:`radar_io.decoding.measurement` — :class:`MeasurementBatch`.
"""

from __future__ import annotations

from radar_io.decoding.batch_decoder import BLOCK_FRAMES, BatchDecoder, decode_bytes, iter_decode
from radar_io.decoding.frame_decoder import FrameDecoder, construct_struct, frame_struct
from radar_io.decoding.measurement import MeasurementBatch
from radar_io.decoding.model import (
                                     COMPENSATIONS,
                                     DECODE_COLUMNS,
                                     GEODETIC_COLUMNS,
                                     POSITION_COLUMNS,
                                     RUNWAY_COLUMNS,
                                     DecodeModel,
                                     output_columns,
)

__all__ = ["BLOCK_FRAMES", "COMPENSATIONS", "DECODE_COLUMNS", "GEODETIC_COLUMNS",
           "POSITION_COLUMNS", "RUNWAY_COLUMNS", "BatchDecoder", "DecodeModel", "FrameDecoder",
           "MeasurementBatch", "construct_struct", "decode_bytes", "frame_struct", "iter_decode",
           "output_columns"]
