"""The decode description: words → units → servo-lag compensation → biases → coordinates.

One description, two evaluators: :class:`~radar_io.decoding.frame_decoder.FrameDecoder`
(one frame, Python floats) and :class:`~radar_io.decoding.batch_decoder.BatchDecoder`
(numpy columns) both read the steps from a :class:`DecodeModel` built here from
the frame spec, the calibration and the site (radar-interface.md §4–§5):

1. words → units: each field's value = counts(raw) × lsb, counts by its encoding
   (unsigned, two's complement, offset binary); status flags by mask and shift;
2. servo-lag compensation and calibration biases, per :data:`COMPENSATIONS`:
   ``SR^ = SR + DSR + ΔSR``, ``EL^ = EL + DEL + ΔEL``, ``AZ^ = (AZ + DAZ + ΔAZ) mod 360``
   — only for RX_GOOD = 1 (an NG sample gets None / NaN);
3. coordinates in the radar frame (X north, Y east, H up):
   ``X = SR^ cos EL^ cos AZ^``, ``Y = SR^ cos EL^ sin AZ^``, ``H = SR^ sin EL^``;
   with a site, the runway frame and WGS-84 geodetic (``coordinates.transforms``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from radar_io.coordinates.transforms import Site
from radar_io.decoding.biases import Calibration
from radar_io.errors import SpecError
from radar_io.wirespec.frame import FieldSpec, FrameSpec, load_spec

DECODE_COLUMNS: tuple[str, ...] = (
    "seq", "tod_s", "sr_m", "dsr_m", "el_deg", "del_deg", "az_deg", "daz_deg",
    "go", "rx_good", "sync", "sr_c_m", "el_c_deg", "az_c_deg", "x_m", "y_m", "h_m",
)
RUNWAY_COLUMNS: tuple[str, ...] = ("xr_m", "yr_m", "hr_m")
GEODETIC_COLUMNS: tuple[str, ...] = ("lat_deg", "lon_deg", "hae_m")
COORDINATE_COLUMNS: tuple[str, ...] = ("x_m", "y_m", "h_m")
#: columns that are empty (None / NaN) for an NG sample
POSITION_COLUMNS: tuple[str, ...] = ("sr_c_m", "el_c_deg", "az_c_deg", *COORDINATE_COLUMNS,
                                     *RUNWAY_COLUMNS, *GEODETIC_COLUMNS)
#: units whose values stay integer counts (no LSB scaling)
INT_UNITS = ("count", "bits")
#: the columns the outputs require, by word name
REQUIRED_COLUMNS = {"seq": "seq", "tod": "tod_s", "sr": "sr_m", "dsr": "dsr_m", "el": "el_deg",
                    "del": "del_deg", "az": "az_deg", "daz": "daz_deg"}


@dataclass(frozen=True)
class Compensation:
    """One compensated quantity: ``column = (value(word) + value(error) + bias) [mod wrap]``."""

    column: str              #: output column, e.g. ``el_c_deg``
    word: str                #: main word, e.g. ``el``
    error: str               #: servo-error word, e.g. ``del``
    bias: str                #: Calibration attribute, e.g. ``del_deg``
    wrap: float | None = None  #: modulo (degrees) or None


#: servo-lag compensation + calibration bias, radar-interface.md §4 steps 2–3, in (SR, EL, AZ) order
COMPENSATIONS: tuple[Compensation, ...] = (
    Compensation("sr_c_m", "sr", "dsr", "dsr_m"),
    Compensation("el_c_deg", "el", "del", "del_deg"),
    Compensation("az_c_deg", "az", "daz", "daz_deg", 360.0),
)


def output_columns(spec: FrameSpec, site: Site | None = None) -> tuple[str, ...]:
    """All columns a decoder built from ``spec`` (and ``site``) produces, in output order."""
    fixed = set(DECODE_COLUMNS)
    extra = [f.name for f in spec.flags if f.name not in fixed]
    extra += [f.column for f in spec.fields if f.column not in fixed]
    cols = [*DECODE_COLUMNS, *extra]
    if site is not None:
        cols += [*RUNWAY_COLUMNS, *GEODETIC_COLUMNS]
    return tuple(cols)


def check_columns(spec: FrameSpec) -> dict[str, str]:
    """Map word name → its column, checking the spec names the columns the outputs require."""
    col = {f.name: f.column for f in spec.fields}
    for name, column in REQUIRED_COLUMNS.items():
        if col.get(name) != column:
            raise SpecError(f"{spec.path}: field {name!r} must have column = {column!r}")
    return col


def value_table(f: FieldSpec) -> np.ndarray:
    """Engineering value for every raw code the (plausible) word can hold, by the spec's encoding."""
    return f.counts_array(np.arange(1 << f.bits, dtype=np.int64)) * f.lsb


@dataclass(frozen=True)
class BoundCompensation:
    """A :class:`Compensation` with its columns resolved and its bias value."""

    column: str
    word: str
    error: str
    word_column: str
    error_column: str
    bias: float
    wrap: float | None


class DecodeModel:
    """Everything both decoders evaluate, built once from spec, calibration and site."""

    def __init__(self, spec: FrameSpec | None = None, calibration: Calibration | None = None,
                 site: Site | None = None) -> None:
        self.spec = spec = spec or load_spec()
        self.site = site
        self.word_columns = check_columns(spec)
        self.columns = output_columns(spec, site)
        self.fields: tuple[FieldSpec, ...] = spec.fields
        self.flags = tuple((f.name, f.mask, f.shift) for f in spec.flags)
        self.status_field = spec.status_field
        self.int_columns = frozenset(f.column for f in spec.fields if f.unit in INT_UNITS)
        self.flag_columns = frozenset(f.name for f in spec.flags)
        self.set_calibration(calibration or Calibration())

    def set_calibration(self, cal: Calibration) -> None:
        self.calibration = cal
        self.compensations = tuple(
            BoundCompensation(c.column, c.word, c.error, self.word_columns[c.word],
                              self.word_columns[c.error], float(getattr(cal, c.bias)), c.wrap)
            for c in COMPENSATIONS)

    def dtype(self, column: str) -> type:
        """numpy dtype of a column: uint8 flags, int64 counts, float64 values."""
        if column in self.flag_columns:
            return np.uint8
        if column in self.int_columns:
            return np.int64
        return np.float64

    def is_scaled(self, f: FieldSpec) -> bool:
        """True when the field's value is counts × lsb (not an integer count or bit field)."""
        return f.unit not in INT_UNITS
