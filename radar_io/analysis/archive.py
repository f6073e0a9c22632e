"""Campaign archive: recordings → one Hive-partitioned Parquet dataset.

Layout (one file per recording)::

    OUT/site=<site>/date=<YYYY-MM-DD>/recording=<stem>/part-0.parquet

Each file has the columns, units and metadata of ``radar-io decode -o X.parquet``
(:mod:`radar_io.sinks.table_parquet`); the partition values are in the path only, as
Hive readers expect (DuckDB ``hive_partitioning``, polars/pandas via pyarrow datasets,
Spark). The framer counters (``frames``, ``crc_errors``, ``bytes_discarded``,
``seq_gaps``) and the recording's damage counters are in the footer metadata
(``radar_io.*``), so "CRC errors per day" needs no second pass over the raw data.

The site is the one given, else the recording header's site name, else ``unknown``;
the date is the UTC date of the first chunk (recording) or the file's modification
time (raw capture). A re-run skips a recording whose archived file names the same
source SHA-256 and options, and rewrites it otherwise (atomically: never a half file).
Memory is constant: the recording is read and decoded in blocks.

The recording's events (``<id>.events.jsonl``: GO edges, sync, clock steps, alarms,
annotations — test points among them) go beside its frames as ``events.jsonl`` in the same
partition, one JSON object per line with fixed columns (:data:`EVENT_COLUMNS`): DuckDB
reads them with ``read_json('OUT/**/events.jsonl', hive_partitioning = true)`` and joins
them to the frames on ``recording``; the ``OUT/**/*.parquet`` globs still see frames only.
"""

from __future__ import annotations

import datetime as _dt
import os
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from radar_io.errors import ConfigError

#: the file inside each recording's partition
PART_NAME = "part-0.parquet"
#: the recording's events beside its frames (JSON lines, one fixed set of columns)
EVENTS_NAME = "events.jsonl"
#: the columns of the events table (absent fields are null)
EVENT_COLUMNS = ("kind", "t_ns", "t_s", "mono_ns", "annotation_kind", "label", "text", "id", "actor",
                 "edge", "seq", "tod_s", "name", "step_s")
#: extensions collected when a directory is given
RECORDING_SUFFIXES = (".rdrlog",)


@dataclass
class ArchiveResult:
    """What :func:`archive_recording` did with one recording."""

    source: Path
    path: Path
    rows: int
    written: bool  # False: already archived with the same SHA-256 and options
    stats: dict[str, int]
    problems: list[str]


def partition_value(text: str) -> str:
    """A partition value safe in a path and in Hive syntax (no ``/``, ``=``, spaces)."""
    v = re.sub(r"[^A-Za-z0-9._+-]+", "_", text.strip()).strip("._")
    return v or "unknown"


def _recording_info(path: Path) -> tuple[str | None, str]:
    """(site name in the header or None, UTC date YYYY-MM-DD) of a recording or capture."""
    from radar_io.recording.rdrlog import RecordingReader, is_recording

    if is_recording(path):
        with RecordingReader(path) as r:
            site = r.header.get("site") or {}
            name = site.get("name") if isinstance(site, dict) else None
            for chunk in r:  # the first good chunk's receive time
                return name, _date(chunk.t_ns / 1e9)
            created = str(r.header.get("created_utc", ""))
            return name, created[:10] if created else _date(path.stat().st_mtime)
    return None, _date(path.stat().st_mtime)


def _date(t_s: float) -> str:
    return _dt.datetime.fromtimestamp(t_s, _dt.UTC).strftime("%Y-%m-%d")


def partition_path(out_dir: str | os.PathLike[str], site: str, date: str, recording: str) -> Path:
    """``OUT/site=…/date=…/recording=…/part-0.parquet``."""
    return (Path(out_dir) / f"site={partition_value(site)}" / f"date={date}"
            / f"recording={partition_value(recording)}" / PART_NAME)


def _archived_meta(path: Path) -> dict[str, str] | None:
    """The ``radar_io.*`` footer metadata of an existing archive file (None if unreadable)."""
    import pyarrow.parquet as pq

    try:
        kv = pq.read_metadata(path).metadata or {}
    except Exception:  # noqa: BLE001 - a damaged or foreign file is simply rewritten
        return None
    return {k.decode()[9:]: v.decode() for k, v in kv.items() if k.startswith(b"radar_io.")}


def archive_recording(path: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
                      site: Any = None, spec: Any = None, calibration: Any = None,
                      reference_path: Any = None, force: bool = False) -> ArchiveResult:
    """Decode one recording (or raw capture) into its partition of the archive at ``out_dir``.

    ``site``: a :class:`~radar_io.coordinates.transforms.Site` (adds the runway and
    geodetic columns and names the partition) or a site name, or None (the header's);
    ``calibration``: radar biases; ``reference_path``: adds ``dy_m, dz_m, along_m, leg``.
    Idempotent: an up-to-date file is left alone unless ``force``.
    """
    from radar_io.coordinates.reference_path import add_deviation
    from radar_io.decoding.batch_decoder import iter_decode
    from radar_io.recording.rdrlog import ReadReport, iter_payloads
    from radar_io.sinks.arrow_convert import file_sha256, output_metadata
    from radar_io.sinks.table_parquet import ParquetTableWriter
    from radar_io.wirespec.frame import load_spec

    src = Path(path)
    if not src.is_file():
        raise ConfigError(f"recording not found: {src}")
    spec = spec or load_spec()
    site_obj = site if site is not None and not isinstance(site, str) else None
    header_site, date = _recording_info(src)
    site_name = (site_obj.name if site_obj is not None else site) or header_site or "unknown"
    out = partition_path(out_dir, site_name, date, src.stem)
    sha = file_sha256(src)
    options = {"archive_site": site_name,
               "path_name": getattr(reference_path, "name", "") if reference_path else ""}
    meta = output_metadata(spec, site_obj, calibration, source=src, source_sha256=sha,
                           **options)
    write_events(src, out.parent / EVENTS_NAME)
    if not force and out.exists():
        old = _archived_meta(out)
        keys = ("source_sha256", "spec_sha256", "calibration_id", "site", "archive_site",
                "path_name")
        if old is not None and all(old.get(k) == meta.get(k) for k in keys):
            return ArchiveResult(src, out, int(old.get("frames", 0)), False,
                                 {k: int(old[k]) for k in ("frames", "crc_errors", "implausible",
                                                           "bytes_discarded", "seq_gaps")
                                  if k in old}, [])
    out.parent.mkdir(parents=True, exist_ok=True)
    report = ReadReport()
    writer = ParquetTableWriter(str(out), metadata=meta)
    writer.open()
    stats: dict[str, int] = {}
    try:
        chunks = iter_payloads(src, chunk_bytes=1 << 20, report=report)
        for batch in iter_decode(chunks, spec=spec, calibration=calibration, site=site_obj):
            if reference_path is not None:
                batch = add_deviation(batch, reference_path)
            writer.write(batch)
            stats = batch.stats
        writer.final_metadata.update({k: str(v) for k, v in stats.items()})
        writer.final_metadata.update({
            "corrupt_chunks": str(report.corrupt_chunks),
            "skipped_bytes": str(report.skipped_bytes),
            "torn_tail_bytes": str(report.torn_tail_bytes)})
        writer.close()
    except BaseException:
        writer.abort()
        raise
    return ArchiveResult(src, out, writer.rows, True, dict(stats), list(report.problems))


def write_events(src: Path, out: Path) -> int:
    """The recording's ``<id>.events.jsonl`` (go, sync, clock_step, alarm, annotation) as
    the partition's events table: every line with the :data:`EVENT_COLUMNS` (null when
    absent; ``name`` is an alarm's; ``t_s``: seconds from the recording's first chunk,
    the report's time axis); none when the recording has no events file. Written to a
    temporary file and renamed; returns the rows."""
    from radar_io.recording.rdrlog import RecordingReader
    from radar_io.sinks.ch10 import read_events_file

    side = src.with_suffix(".events.jsonl")
    if not side.is_file():
        return 0
    with RecordingReader(src) as r:
        t0 = next((c.t_ns for c in r), None)
    rows = [{**{c: e.get(c) for c in EVENT_COLUMNS},
             "kind": e.get("kind") or e.get("type"),  # the alarm engine's records say "type"
             "t_s": (e["t_ns"] - t0) / 1e9 if isinstance(e.get("t_ns"), int) and t0 else None}
            for e in read_events_file(side)]
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    import json

    with open(tmp, "w", encoding="utf-8") as f:
        f.writelines(json.dumps(r, default=str) + "\n" for r in rows)
    os.replace(tmp, out)
    return len(rows)


def find_recordings(inputs: Iterable[str | os.PathLike[str]]) -> Iterator[Path]:
    """The files named, and the ``.rdrlog`` files under the directories named (sorted)."""
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            yield from sorted(q for q in p.rglob("*") if q.is_file()
                              and q.suffix in RECORDING_SUFFIXES)
        elif p.is_file():
            yield p
        else:
            raise ConfigError(f"recording not found: {p}")


def archive(inputs: Iterable[str | os.PathLike[str]], out_dir: str | os.PathLike[str],
            **options: Any) -> Iterator[ArchiveResult]:
    """:func:`archive_recording` for every recording in ``inputs``, one result each."""
    for p in find_recordings(inputs):
        yield archive_recording(p, out_dir, **options)
