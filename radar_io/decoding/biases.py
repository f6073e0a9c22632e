"""Radar calibration sets: the biases ΔSR/ΔEL/ΔAZ the decoder adds (radar-interface.md §4 step 3).

A calibration set is a small versioned JSON document::

    {
      "format": "radar_io-calibration/1",
      "id": "2026-11-21-flight-7",
      "created_utc": "2026-11-21T19:40:00Z",
      "biases": {"dsr_m": 3.1, "del_deg": -0.012, "daz_deg": 0.034},
      "statistics": {...},      # optional: what the bias estimate reported
      "provenance": {...}       # optional: inputs, their hashes, who/what made it
    }

``SR^ = SR' + dsr_m``, ``EL^ = EL' + del_deg``, ``AZ^ = AZ' + daz_deg`` (metres and degrees).
The all-zero set (id ``"none"``) is the default.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
from dataclasses import dataclass, field
from typing import Any, Final

from radar_io.errors import ConfigError, StorageError
from radar_io.textfiles import Fields, read_json, show

FORMAT: Final = "radar_io-calibration/1"
#: keys of a calibration set document
TOP_KEYS = ("format", "id", "created_utc", "biases", "statistics", "provenance")
#: bias → largest magnitude accepted (m, deg, deg): beyond that the set is a mistake, not a bias
BIAS_LIMITS = {"dsr_m": 10_000.0, "del_deg": 90.0, "daz_deg": 180.0}


@dataclass(frozen=True)
class Calibration:
    """Radar biases added after servo-lag compensation (m, deg, deg)."""

    dsr_m: float = 0.0
    del_deg: float = 0.0
    daz_deg: float = 0.0
    id: str = "none"
    created_utc: str = ""
    statistics: dict[str, Any] = field(default_factory=dict, compare=False)
    provenance: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        for name in ("dsr_m", "del_deg", "daz_deg"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise ConfigError(f"calibration bias {name} must be a finite number, got {v!r}")

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of this set (see module docstring)."""
        return {
            "format": FORMAT,
            "id": self.id,
            "created_utc": self.created_utc,
            "biases": {"dsr_m": self.dsr_m, "del_deg": self.del_deg, "daz_deg": self.daz_deg},
            "statistics": self.statistics,
            "provenance": self.provenance,
        }

    @classmethod
    def from_dict(cls, doc: Any, *, source: str = "calibration") -> Calibration:
        """Validate and build a set from its JSON document; raises ConfigError naming the field."""
        f = Fields(doc, source, "calibration set")
        f.only(*TOP_KEYS)
        fmt = f.string("format", default=FORMAT)
        if fmt != FORMAT:
            f.fail("format", f"unsupported calibration format {show(fmt)} (expected {FORMAT!r})")
        biases = f.table("biases")
        assert biases is not None
        biases.only(*BIAS_LIMITS)
        values = {k: biases.number(k, -lim, lim, default=0.0) for k, lim in BIAS_LIMITS.items()}
        return cls(**values,
                   id=f.string("id", default="unnamed", nonempty=True),
                   created_utc=f.string("created_utc", default=""),
                   statistics=f.mapping("statistics"),
                   provenance=f.mapping("provenance"))


def load_calibration(path: str | os.PathLike[str]) -> Calibration:
    """Read a calibration set JSON file; every field is checked (docs/input-validation.md)."""
    doc = read_json(path, "calibration file")
    return Calibration.from_dict(doc, source=str(path))


def save_calibration(cal: Calibration, path: str | os.PathLike[str]) -> None:
    """Write a calibration set durably: a temporary file of its own beside ``path``,
    fsynced, renamed over ``path``, then the directory fsynced
    (:class:`~radar_io.sinks.atomic.AtomicFile`). A power cut leaves the old file or the
    new one, never a mix; StorageError when the disk refuses."""
    from radar_io.sinks.atomic import AtomicFile

    out = AtomicFile(path)
    try:
        out.tmp_path.write_text(json.dumps(cal.to_dict(), indent=2) + "\n", encoding="utf-8")
    except OSError as exc:
        out.abort()
        raise StorageError(f"cannot write {out.path}: {exc.strerror}", errno=exc.errno) from exc
    out.commit()


def utc_now_iso() -> str:
    """Current UTC time as ISO-8601 with a Z suffix (seconds resolution)."""
    return _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat().replace("+00:00", "Z")
