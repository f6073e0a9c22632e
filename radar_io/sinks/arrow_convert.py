"""Measurement batches as Apache Arrow record batches (zero-copy from numpy).

:func:`batch_to_arrow` keeps the decode column names and order, puts each column's
unit in its field metadata (``unit``) and turns NaN into null in the columns where
NaN means "no value" (the compensated and coordinate columns of an NG sample, the
path deviation). Numeric columns without such NaN share the numpy buffer (no copy);
a nullable float column shares its data buffer and gains a validity bitmap.

:func:`output_metadata` is the file metadata every table format carries (spec
version, site, calibration id, source file name and SHA-256).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from radar_io.decoding.model import POSITION_COLUMNS

#: columns where NaN means "no value" (→ null in Arrow, empty in CSV, null in JSON)
NULLABLE_COLUMNS: frozenset[str] = frozenset(
    (*POSITION_COLUMNS, "dy_m", "dz_m", "along_m"))
#: unit by column-name suffix (SI units at the API: the name says the unit)
_SUFFIX_UNITS = (("_mps", "m/s"), ("_m2", "m2"), ("_deg", "deg"), ("_m", "m"), ("_s", "s"), ("_hz", "Hz"))
#: columns whose unit the suffix cannot say
_NAMED_UNITS = {"seq": "count", "status_raw": "bits", "leg": "count"}
#: prefix of the schema metadata keys radar_io writes
META_PREFIX = "radar_io."


def column_unit(name: str) -> str:
    """Unit of a column: ``sr_m`` → ``m``; flags (``go``, ``sync`` …) → ``1``."""
    if name in _NAMED_UNITS:
        return _NAMED_UNITS[name]
    for suffix, unit in _SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return "1"


def arrow_schema(columns: Sequence[str], dtypes: Mapping[str, np.dtype],
                 metadata: Mapping[str, str] | None = None) -> pa.Schema:
    """The schema of a table of ``columns`` (numpy ``dtypes``), units in field metadata."""
    fields = [pa.field(c, pa.from_numpy_dtype(dtypes[c]), nullable=True,
                       metadata={"unit": column_unit(c)}) for c in columns]
    return pa.schema(fields, metadata={f"{META_PREFIX}{k}": str(v)
                                       for k, v in (metadata or {}).items()})


def batch_to_arrow(batch: Any, metadata: Mapping[str, str] | None = None,
                   schema: pa.Schema | None = None) -> pa.RecordBatch:
    """A :class:`pyarrow.RecordBatch` of a measurement batch (columns in decode order).

    ``batch`` is a :class:`~radar_io.decoding.decoders.MeasurementBatch` (or any mapping
    with ``columns``); ``metadata`` goes into the schema under ``radar_io.<key>``.
    Pass ``schema`` (from an earlier call) to skip rebuilding it for each batch.
    """
    columns = tuple(getattr(batch, "columns", None) or batch.keys())
    arrays = []
    for c in columns:
        a = np.ascontiguousarray(batch[c])
        if a.dtype.kind == "f" and c in NULLABLE_COLUMNS:
            arrays.append(pa.array(a, from_pandas=True))  # NaN → null; data buffer shared
        else:
            arrays.append(pa.array(a))
    if schema is None:
        schema = arrow_schema(columns, {c: np.asarray(batch[c]).dtype for c in columns}, metadata)
    return pa.RecordBatch.from_arrays(arrays, schema=schema)


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of a file, read in 1 MiB pieces."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def output_metadata(spec: Any = None, site: Any = None, calibration: Any = None,
                    source: str | os.PathLike[str] | None = None,
                    source_sha256: str | None = None, **extra: Any) -> dict[str, str]:
    """The file metadata of a decoded table: spec version, site, calibration id, source.

    ``source`` is the input file (its base name is stored; its SHA-256 is computed
    unless given). Values are strings (Parquet / Arrow key-value metadata).
    """
    from radar_io import __version__

    meta: dict[str, str] = {"software": f"radar_io {__version__}"}
    if spec is not None:
        meta["spec"] = str(spec.name)
        meta["spec_version"] = str(spec.spec_version)
        meta["spec_sha256"] = str(spec.sha256)
    meta["site"] = str(site.name) if site is not None else ""
    meta["calibration_id"] = str(calibration.id) if calibration is not None else "none"
    if source is not None and str(source) != "-":
        meta["source_file"] = os.path.basename(os.fspath(source))
        meta["source_sha256"] = source_sha256 or file_sha256(source)
    meta.update({k: str(v) for k, v in extra.items()})
    return meta


def read_metadata(schema: pa.Schema) -> dict[str, str]:
    """The ``radar_io.*`` metadata of a schema, without the prefix."""
    out = {}
    for k, v in (schema.metadata or {}).items():
        key = k.decode()
        if key.startswith(META_PREFIX):
            out[key[len(META_PREFIX):]] = v.decode()
    return out
