"""Fuzzing with hypothesis: the file loaders, ``decode_bytes``, the framers under random
chunking and the recording reader never fail with anything but their own error.

Short runs here (``FUZZ_EXAMPLES`` inputs per target, default 150); the longer run and
its figures are in docs/fuzzing.md (same tests, ``FUZZ_EXAMPLES=...``).
"""

from __future__ import annotations

import itertools
import json
import math
import os
import struct
import zlib
from pathlib import Path
from typing import Any

import independent
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from radar_io.errors import RecordingError, ValidationError

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "150"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])

SITE_DOC: dict[str, Any] = {
    "name": "fuzz", "radar": {"lat_deg": 35.5, "lon_deg": 139.7, "h_m": 45.0},
    "runway": {"heading_deg": 340.0, "radar_xr_m": 350.0, "radar_yr_m": 1200.0, "radar_hr_m": 3.0},
    "asterix": {"sac": 0, "sic": 1}}
PATH_DOC: dict[str, Any] = {
    "frame": "runway", "turn_radius_m": 1500.0,
    "points": [{"x_m": -12000.0, "y_m": -6000.0, "h_m": 539.1},
               {"x_m": -12000.0, "y_m": 0.0, "h_m": 539.1},
               {"x_m": 0.0, "y_m": 0.0, "h_m": 15.0}]}
CAL_DOC: dict[str, Any] = {"format": "radar_io-calibration/1", "id": "fuzz",
                           "biases": {"dsr_m": 3.1, "del_deg": -0.012, "daz_deg": 0.034}}
DBC_TEXT = (ROOT / "firmware_specs" / "airdata.dbc").read_text(encoding="utf-8")
CSV_TEXT = ("group,radar_sr_m,radar_el_deg,radar_az_deg,photo_sr_m,photo_el_deg,photo_az_deg\n"
            "A,1000,1.0,10.0,1001,1.01,10.02\nB,2000,2.0,20.0,2001,2.01,20.02\n")


# ------------------------------------------------------------------ TOML written by hand
def toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def to_toml(doc: dict[str, Any]) -> str:
    out = [f"{json.dumps(k)} = {toml_value(v)}" for k, v in doc.items()
           if not isinstance(v, dict) and not (isinstance(v, list) and v and
                                               all(isinstance(x, dict) for x in v))]
    for k, v in doc.items():
        if isinstance(v, dict):
            out.append(f"[{json.dumps(k)}]")
            out += [f"{json.dumps(str(kk))} = {toml_value(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for x in v:
                out.append(f"[[{json.dumps(k)}]]")
                out += [f"{json.dumps(str(kk))} = {toml_value(vv)}" for kk, vv in x.items()]
    return "\n".join(out) + "\n"


scalars = st.one_of(st.integers(-2**63, 2**63 - 1), st.floats(), st.booleans(),
                    st.text(max_size=20), st.sampled_from([0, 1, -1, 255, 256, 90.0, -90.0, 1e300]))
values = st.one_of(scalars, st.lists(scalars, max_size=3),
                   st.dictionaries(st.text(max_size=5), scalars, max_size=2))
keys = st.one_of(st.sampled_from(["name", "description", "radar", "runway", "asterix", "lat_deg",
                                  "lon_deg", "h_m", "heading_deg", "radar_xr_m", "sac", "sic",
                                  "frame", "turn_radius_m", "points", "x_m", "y_m", "biases",
                                  "dsr_m", "del_deg", "daz_deg", "format", "id", "statistics"]),
                 st.text(min_size=1, max_size=8))


@st.composite
def mutated(draw: Any, base: dict[str, Any]) -> dict[str, Any]:
    """``base`` with 1-3 random edits: a value replaced, a key added or deleted, at any depth."""
    doc = json.loads(json.dumps(base))
    for _ in range(draw(st.integers(1, 3))):
        tables = [doc] + [v for v in doc.values() if isinstance(v, dict)] + \
                 [x for v in doc.values() if isinstance(v, list) for x in v if isinstance(x, dict)]
        t = draw(st.sampled_from(tables))
        op = draw(st.sampled_from(["set", "set", "delete", "add"]))
        if op == "delete" and t:
            t.pop(draw(st.sampled_from(sorted(t))))
        elif op == "set" and t:
            t[draw(st.sampled_from(sorted(t)))] = draw(values)
        else:
            t[draw(keys)] = draw(values)
    return doc


def text_mutations(text: str) -> st.SearchStrategy[bytes]:
    """The file's bytes with random bytes inserted, deleted or overwritten."""
    raw = text.encode()

    @st.composite
    def go(draw: Any) -> bytes:
        b = bytearray(raw)
        for _ in range(draw(st.integers(1, 8))):
            i = draw(st.integers(0, len(b)))
            op = draw(st.sampled_from(["ins", "del", "set", "cut"]))
            if op == "ins":
                b[i:i] = draw(st.binary(min_size=1, max_size=4))
            elif op == "del":
                del b[i:i + draw(st.integers(1, 20))]
            elif op == "cut":
                del b[i:]
            elif i < len(b):
                b[i] = draw(st.integers(0, 255))
        return bytes(b)
    return go()


def loader(kind: str) -> Any:
    from radar_io.calibration.tables import read_table
    from radar_io.coordinates.reference_path import load_path
    from radar_io.coordinates.transforms import load_site
    from radar_io.decoding.airdata import load_dbc
    from radar_io.decoding.biases import load_calibration

    def points(p: Path) -> Any:
        t = read_table(p)
        return [t.floats(c) for c in t.columns if c != "group"]
    return {"site": load_site, "path": load_path, "calibration": load_calibration,
            "dbc": load_dbc, "points": points}[kind]


def check_load(kind: str, data: bytes, d: Path) -> None:
    """Load ``data``: it loads, or raises a ValidationError with one line naming the file."""
    f = d / f"fuzz.{kind}"
    f.write_bytes(data)
    try:
        obj = loader(kind)(f)
    except ValidationError as exc:
        msg = str(exc)
        assert "\n" not in msg and str(f) in msg, msg
        return
    if kind == "site":
        assert all(math.isfinite(v) for v in (obj.lat_deg, obj.lon_deg, obj.h_m,
                                              obj.runway_heading_deg, obj.radar_xr_m))
        assert obj.asterix_sac is None or 0 <= obj.asterix_sac <= 255
    elif kind == "path":
        assert np.isfinite(obj.points).all() and obj.turn_radius_m > 0
    elif kind == "calibration":
        assert all(math.isfinite(v) for v in (obj.dsr_m, obj.del_deg, obj.daz_deg))


# ------------------------------------------------------------------ loaders
@pytest.mark.slow
@FUZZ
@given(doc=mutated(SITE_DOC))
def test_fuzz_site_fields(doc, tmp_path):
    check_load("site", to_toml(doc).encode("utf-8", "surrogatepass"), tmp_path)


@pytest.mark.slow
@FUZZ
@given(doc=mutated(PATH_DOC))
def test_fuzz_path_fields(doc, tmp_path):
    check_load("path", to_toml(doc).encode("utf-8", "surrogatepass"), tmp_path)


@pytest.mark.slow
@FUZZ
@given(doc=mutated(CAL_DOC))
def test_fuzz_calibration_fields(doc, tmp_path):
    check_load("calibration", json.dumps(doc).encode("utf-8", "surrogatepass"), tmp_path)


@pytest.mark.slow
@FUZZ
@given(data=st.one_of(text_mutations(to_toml(SITE_DOC)), st.binary(max_size=200)))
def test_fuzz_site_bytes(data, tmp_path):
    check_load("site", data, tmp_path)


@pytest.mark.slow
@FUZZ
@given(data=st.one_of(text_mutations(to_toml(PATH_DOC)), st.binary(max_size=200)))
def test_fuzz_path_bytes(data, tmp_path):
    check_load("path", data, tmp_path)


@pytest.mark.slow
@FUZZ
@given(data=st.one_of(text_mutations(json.dumps(CAL_DOC)), st.binary(max_size=200)))
def test_fuzz_calibration_bytes(data, tmp_path):
    check_load("calibration", data, tmp_path)


@pytest.mark.slow
@FUZZ
@given(data=st.one_of(text_mutations(DBC_TEXT), st.binary(max_size=200)))
def test_fuzz_dbc_bytes(data, tmp_path):
    check_load("dbc", data, tmp_path)


@pytest.mark.slow
@FUZZ
@given(data=st.one_of(text_mutations(CSV_TEXT), st.binary(max_size=200)))
def test_fuzz_calibration_points_bytes(data, tmp_path):
    check_load("points", data, tmp_path)


# ------------------------------------------------------------------ byte paths
def good_frames(n: int, seed: int) -> list[bytes]:
    rng = np.random.default_rng(seed)
    return [independent.frame(seq=i, tod=i * 500, sr=int(rng.integers(0, 65536)),
                              el=int(rng.integers(-2000, 16000)), az=int(rng.integers(0, 65536)),
                              dsr=int(rng.integers(0, 4096)), sts=int(rng.integers(0, 65536)) & 0xF007)
            for i in range(n)]


@st.composite
def streams(draw: Any) -> bytes:
    """Good frames with random garbage, damaged frames and cut frames between them."""
    frames = good_frames(draw(st.integers(0, 30)), draw(st.integers(0, 2**32 - 1)))
    parts: list[bytes] = []
    for fr in frames:
        kind = draw(st.sampled_from(["good", "good", "good", "garbage", "flip", "cut", "sync"]))
        if kind == "garbage":
            parts.append(draw(st.binary(max_size=40)))
        elif kind == "flip":
            b = bytearray(fr)
            b[draw(st.integers(0, 23))] ^= 1 << draw(st.integers(0, 7))
            fr = bytes(b)
        elif kind == "cut":
            fr = fr[:draw(st.integers(0, 23))]
        elif kind == "sync":
            parts.append(b"\xeb\x90" * draw(st.integers(1, 3)))
        parts.append(fr)
    return b"".join(parts)


@st.composite
def chunked(draw: Any) -> tuple[bytes, list[int]]:
    data = draw(streams())
    cuts = sorted(draw(st.lists(st.integers(0, len(data)), max_size=20)))
    return data, cuts


def pieces(data: bytes, cuts: list[int]) -> list[bytes]:
    bounds = [0, *cuts, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(bounds)]


@pytest.mark.slow
@FUZZ
@given(data=st.one_of(st.binary(max_size=600), streams()))
def test_fuzz_decode_bytes(data, spec):
    from radar_io.decoding.decoders import decode_bytes

    batch = decode_bytes(data, spec=spec)
    n = len(batch["seq"])
    assert batch.stats["frames"] == n
    assert batch.stats["bytes_discarded"] <= len(data)
    assert n * 24 <= len(data)


@pytest.mark.slow
@FUZZ
@given(case=chunked())
def test_fuzz_framer_random_chunking_equals_one_feed(case, spec):
    from radar_io.framing.framers import BatchFramer, Framer

    data, cuts = case
    one = Framer(spec)
    whole = one.feed(data) + one.flush()
    many = Framer(spec)
    got = [fr for p in pieces(data, cuts) for fr in many.feed(p)] + many.flush()
    assert got == whole
    assert many.stats.as_dict() == one.stats.as_dict()
    b1, b2 = BatchFramer(spec), BatchFramer(spec)
    rows1 = [b1.feed(data), b1.flush()]
    rows2 = [b2.feed(p) for p in pieces(data, cuts)] + [b2.flush()]
    cat = lambda rows: b"".join(np.asarray(r).astype(">u2").tobytes() for r in rows)  # noqa: E731
    assert cat(rows2) == cat(rows1) == b"".join(whole)
    assert b2.stats.as_dict() == b1.stats.as_dict() == one.stats.as_dict()


@st.composite
def recordings(draw: Any) -> bytes:
    """An .rdrlog built byte by byte: a (maybe odd) header with a correct CRC, chunks, damage."""
    from radar_io.recording import rdrlog

    header = draw(st.one_of(
        st.just(json.dumps({"format": rdrlog.FORMAT}).encode()),
        st.builds(lambda v: json.dumps(v).encode(), values),
        st.binary(max_size=30)))
    out = bytearray(rdrlog.FILE_MAGIC + struct.pack(">I", len(header)) + header
                    + struct.pack(">I", zlib.crc32(header)))
    for i in range(draw(st.integers(0, 8))):
        out += rdrlog.encode_chunk(draw(st.binary(max_size=60)), i * 1000)
    for _ in range(draw(st.integers(0, 3))):
        op = draw(st.sampled_from(["flip", "cut", "ins"]))
        i = draw(st.integers(0, len(out)))
        if op == "flip" and i < len(out):
            out[i] ^= 1 << draw(st.integers(0, 7))
        elif op == "cut":
            del out[i:]
        else:
            out[i:i] = draw(st.binary(min_size=1, max_size=8))
    return bytes(out)


@pytest.mark.slow
@FUZZ
@given(data=recordings())
def test_fuzz_recording_reader(data, tmp_path):
    from radar_io.recording.rdrlog import RecordingReader

    f = tmp_path / "fuzz.rdrlog"
    f.write_bytes(data)
    try:
        with RecordingReader(f) as r:
            chunks = list(r)
            rep = r.report
    except RecordingError as exc:
        assert "\n" not in str(exc)
        return
    assert rep.chunks == len(chunks)
    assert sum(len(c.data) for c in chunks) == rep.bytes <= len(data)

