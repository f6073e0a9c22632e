"""Radar readings at the sync (camera shutter) events of a recording (calibration.md §8).

The readings paired with photo positions are the servo-compensated SR', EL', AZ'
(radar-interface.md §4 step 2) *without* any calibration bias: the bias is what
the pairs estimate.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from radar_io.decoding.batch_decoder import iter_decode
from radar_io.recording.rdrlog import iter_payloads
from radar_io.wirespec.frame import FrameSpec


def radar_at_sync_events(path: str | os.PathLike[str], spec: FrameSpec | None = None
                         ) -> list[dict[str, Any]]:
    """One entry per SYNC 0→1 edge, in order: index, SEQ, TOD and SR'/EL'/AZ' (None when NG).

    A recording that starts with SYNC already high holds a shutter event whose instant was
    not seen: it is counted (so the numbering follows the shutter count) but marked
    ``complete: false`` with no readings, and cannot be paired with a photo.
    """
    events: list[dict[str, Any]] = []
    last = -1  # before the first frame
    for b in iter_decode(iter_payloads(path), spec=spec):
        if not len(b):
            continue
        sync = b["sync"].astype(np.int8)
        prev = np.concatenate(([last], sync[:-1]))
        for i in np.flatnonzero((sync == 1) & (prev != 1)).tolist():
            complete = bool(prev[i] == 0)
            good = bool(b["rx_good"][i]) and complete
            events.append({
                "sync_index": len(events), "seq": int(b["seq"][i]), "tod_s": float(b["tod_s"][i]),
                "complete": complete, "rx_good": good,
                "sr_m": float(b["sr_c_m"][i]) if good else None,
                "el_deg": float(b["el_c_deg"][i]) if good else None,
                "az_deg": float(b["az_c_deg"][i]) if good else None,
            })
        last = int(sync[-1])
    return events
