"""Old home of the framers; they live in :mod:`radar_io.framing.core` (one core for RDR1 and TLM1)."""

from __future__ import annotations

from radar_io.framing.core import (
                                   BatchFramer,
                                   FrameFormat,
                                   Framer,
                                   FramerStats,
                                   FrameValidator,
                                   SeqCounter,
                                   WordCheck,
                                   field_raw,
)

_SeqTracker = SeqCounter  # the old private name

__all__ = ["BatchFramer", "FrameFormat", "FrameValidator", "Framer", "FramerStats", "SeqCounter",
           "WordCheck", "field_raw"]
