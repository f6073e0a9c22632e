"""``radar-io track`` end to end, as separate processes: simulate → track, formats, errors."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import ROOT, run_cli
from radar_io.decoding.batch_decoder import decode_bytes
from radar_io.recording.rdrlog import iter_payloads
from radar_io.sinks.arrow_convert import read_metadata
from radar_io.tracking.tracker import TRACK_COLUMNS, TrackParams, track_batch


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    rec = tmp_path_factory.mktemp("trk") / "approach.rdrlog"
    r = run_cli("simulate", "-o", str(rec), "--duration-s", "20", "--ng-per-min", "10", "-q")
    assert r.returncode == 0, r.stderr
    return rec


def test_track_to_parquet_with_site_and_path(recording, tmp_path):
    out = tmp_path / "bet.parquet"
    path = ROOT / "firmware_specs" / "paths" / "demo_approach_runway.toml"
    r = run_cli("track", str(recording), "-o", str(out), "--site", "demo", "--path", str(path),
                "--q-mps2", "0.8")
    assert r.returncode == 0, r.stderr
    assert "outliers" in r.stderr.decode()
    t = pq.read_table(out)
    assert tuple(t.column_names[:len(TRACK_COLUMNS)]) == TRACK_COLUMNS
    assert {"xr_m", "lat_deg", "dy_m", "leg"} <= set(t.column_names)
    meta = read_metadata(t.schema)
    assert meta["tracking.model"] == "cv" and meta["tracking.q_mps2"] == "0.8"
    assert meta["tracking.sigma_range_m"] == "5.0"      # from the demo site file
    assert meta["tracking.estimate"] == "rts_smoothed"
    assert int(meta["tracking.outliers"]) == int(np.sum(t["outlier"].to_numpy()))
    footer = {k.decode(): v.decode() for k, v in pq.read_metadata(out).metadata.items()}
    assert footer["radar_io.tracking.used"] == meta["tracking.used"]
    assert int(footer["radar_io.frames"]) == t.num_rows
    assert t.schema.field("gs_mps").metadata[b"unit"] == b"m/s"
    # the file holds what the API computes on the same measurements
    batch = decode_bytes(b"".join(iter_payloads(recording)))
    api = track_batch(batch, TrackParams(q_mps2=0.8))
    assert t.num_rows == len(batch)
    np.testing.assert_array_equal(t["x_m"].to_numpy(), api["x_m"])
    np.testing.assert_array_equal(t["vh_sigma_mps"].to_numpy(), api["vh_sigma_mps"])


def test_forward_only_csv_and_overrides(recording, tmp_path):
    out = tmp_path / "fwd.csv"
    r = run_cli("track", str(recording), "-o", str(out), "--forward-only",
                "--sigma-range-m", "1", "--sigma-angle-deg", "0.005", "-q")
    assert r.returncode == 0, r.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == ",".join(TRACK_COLUMNS) and len(lines) == 20_001
    assert r.stderr == b""


@pytest.mark.parametrize("args, message", [
    (["{tmp}/missing.rdrlog", "-o", "{tmp}/x.parquet"], "input not found: "),
    (["{rec}", "-o", "{tmp}/x.parquet", "--q-mps2", "0"], "--q-mps2: expected a positive number"),
    (["{rec}", "-o", "{tmp}/x.parquet", "--site", "{bad}"], "field radar.sigma_range_m"),
])
def test_bad_input_is_one_line_and_exit_2(recording, tmp_path, args, message):
    bad = tmp_path / "site.toml"
    bad.write_text((ROOT / "firmware_specs" / "sites" / "demo.toml").read_text()
                   .replace("sigma_range_m = 5.0", "sigma_range_m = -5.0"))
    argv = [a.format(rec=recording, bad=bad, tmp=tmp_path) for a in args]
    r = run_cli("track", *argv)
    err = r.stderr.decode().strip()
    assert r.returncode == 2 and len(err.splitlines()) == 1 and message in err, err
    if "site" in message:
        assert str(bad) in err
    assert not (tmp_path / "x.parquet").exists()
