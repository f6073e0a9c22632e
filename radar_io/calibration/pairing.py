"""Pair photo positions with the radar at recorded sync events and estimate the biases
(calibration.md §8). Pure: the sync events are passed in, nothing is read or applied.

A photo observation gives the aircraft position at a camera shutter (a SYNC 0→1 edge of
a recording, numbered by ``sync_index``) either as ground-frame ``photo_x_m``,
``photo_y_m``, ``photo_z_m`` (north, east, down of the radar; m) or as radar
coordinates ``photo_sr_m``, ``photo_el_deg``, ``photo_az_deg``. The radar's SR'/EL'/AZ'
at that edge (m, deg) are subtracted per group: ΔSR = SR_photo − SR', and so on.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from radar_io.errors import ValidationError

_PAIR_AXES = (("photo_sr_m", "radar_sr_m"), ("photo_el_deg", "radar_el_deg"),
              ("photo_az_deg", "radar_az_deg"))


def pair_observations(observations: Sequence[Mapping[str, Any]],
                      events: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[dict[str, Any]]:
    """One pair per observation: the photo's SR/EL/AZ (m, deg) beside the radar's at the
    sync event ``events[recording][sync_index]``. ValidationError names the observation
    and the reason (index out of range, event before the recording, radar NG, no position).
    """
    from radar_io.calibration.bias import photo_to_radar

    pairs = []
    for k, ob in enumerate(observations):
        rec, idx = ob["recording"], ob["sync_index"]
        evs = events.get(rec, ())
        if idx >= len(evs):
            raise ValidationError(f"observation {k}: recording {rec} has {len(evs)} sync events, "
                                  f"no index {idx}")
        ev = evs[idx]
        if not ev["complete"]:
            raise ValidationError(f"observation {k}: sync event {idx} of {rec} began before "
                                  "the recording")
        if not ev["rx_good"]:
            raise ValidationError(f"observation {k}: the radar was NG at sync event {idx} of {rec}")
        xyz: list[Any] = [ob.get(c) for c in ("photo_x_m", "photo_y_m", "photo_z_m")]
        sea: list[Any] = [ob.get(c) for c in ("photo_sr_m", "photo_el_deg", "photo_az_deg")]
        if None not in xyz:
            sr, el, az = (float(v[0]) for v in photo_to_radar(*(np.array([v]) for v in xyz)))
        elif None not in sea:
            sr, el, az = (float(v) for v in sea)
        else:
            raise ValidationError(f"observation {k}: give photo_x_m/y_m/z_m or "
                                  "photo_sr_m/el_deg/az_deg")
        pairs.append({"group": ob["group"], "recording": rec, "sync_index": idx,
                      "seq": ev["seq"], "tod_s": ev["tod_s"], "radar_sr_m": ev["sr_m"],
                      "radar_el_deg": ev["el_deg"], "radar_az_deg": ev["az_deg"],
                      "photo_sr_m": sr, "photo_el_deg": el, "photo_az_deg": az})
    return pairs


def estimate_bias(observations: Sequence[Mapping[str, Any]],
                  events: Mapping[str, Sequence[Mapping[str, Any]]], cal_id: str,
                  method: str = "calibration.md §8") -> dict[str, Any]:
    """Pairs, per-group and combined statistics, and the proposed calibration set
    (``{"pairs", "statistics", "calibration"}``); nothing is applied."""
    from radar_io.calibration.bias import bias_calibration, bias_statistics

    pairs = pair_observations(observations, events)
    groups = [p["group"] for p in pairs]
    photo = tuple(np.array([p[a] for p in pairs]) for a, _ in _PAIR_AXES)
    radar = tuple(np.array([p[b] for p in pairs]) for _, b in _PAIR_AXES)
    stats = bias_statistics(groups, photo, radar)
    cal = bias_calibration(stats, cal_id=cal_id, provenance={
        "method": method, "recordings": sorted({p["recording"] for p in pairs}),
        "pairs": len(pairs)})
    return {"pairs": pairs, "statistics": stats, "calibration": cal.to_dict()}
