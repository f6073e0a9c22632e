"""Annotations (issue 22 item 1): test points marked live on a real uvicorn appear in
``GET /api/annotations``, in the report's test-point table, in the archive's events table
(read by DuckDB beside the frames) and in the Chapter 10 export; ``radar-io annotate`` adds
one after the flight."""

from __future__ import annotations

import json
import time

import pytest

from radar_io.cli.main import main as cli_main
from radar_io.service.auth import TokensFile
from radar_io.service.config import ServiceConfig
from radar_io.wirespec.frame import spec_dir

from .liveserver import live_server
from .test_live_never_stops import call

PATH = spec_dir() / "paths" / "demo_track_radar.toml"


def _wait_frames(srv, n: int, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while srv.get("/api/status").get("frames", 0) < n:
        assert time.monotonic() < deadline, "no frames"
        time.sleep(0.1)


def test_live_test_points_reach_api_report_archive_and_ch10(tmp_path):
    tf = TokensFile(tmp_path / "tokens.json")
    op, viewer = tf.add("op", "operator"), tf.add("view", "viewer")
    cfg = ServiceConfig(source="sim://", data_dir=str(tmp_path / "data"),
                        tokens_file=str(tf.path), auto_record="manual", path=str(PATH))
    with live_server(cfg) as srv:
        srv.wait_connected()
        code, early = call(srv.base, "POST", "/api/annotations",
                           {"kind": "note", "label": "pre", "text": "before recording"}, token=op)
        assert code == 201 and early["recording"] is None  # kept in the service log
        assert call(srv.base, "POST", "/api/annotations", {"kind": "marker"},
                    token=viewer)[0] == 403
        code, doc = call(srv.base, "POST", "/api/recordings/start", token=op)
        assert code == 200
        rec = doc["recording"]
        time.sleep(1.0)
        made = []
        for kind, label, text in (("test_point_start", "TP1", "level 600 m"),
                                  ("marker", "", "gust"), ("test_point_end", "TP1", "")):
            code, a = call(srv.base, "POST", "/api/annotations",
                           {"kind": kind, "label": label, "text": text}, token=op)
            assert code == 201 and a["recording"] == rec and a["id"], a
            made.append(a)
            time.sleep(1.0)
        # one dated back into the recording, given its t_ns
        code, a = call(srv.base, "POST", "/api/annotations",
                       {"kind": "note", "label": "late", "t_ns": made[1]["t_ns"] + 500_000_000},
                       token=op)
        assert code == 201 and a["recording"] == rec
        made.append(a)
        time.sleep(0.5)
        assert call(srv.base, "POST", "/api/recordings/stop", token=op)[0] == 200
        listed = srv.get(f"/api/annotations?recording={rec}")["annotations"]
        every = srv.get("/api/annotations")["annotations"]
        events = srv.get(f"/api/recordings/{rec}/events")
    assert [x["id"] for x in listed] == [m["id"] for m in sorted(made, key=lambda m: m["t_ns"])]
    assert [x["kind"] for x in listed] == ["test_point_start", "marker", "note", "test_point_end"]
    assert all(x["actor"] == "op" and x["recording"] == rec for x in listed)
    assert {x["id"] for x in every} == {m["id"] for m in made} | {early["id"]}
    assert any(e.get("kind") == "annotation" for e in
               (events if isinstance(events, list) else events.get("events", [])))
    rec_path = tmp_path / "data" / "recordings" / f"{rec}.rdrlog"
    lines = [json.loads(x) for x in rec_path.with_suffix(".events.jsonl").read_text().splitlines()]
    notes = [e for e in lines if e["kind"] == "annotation"]
    assert len(notes) == 4 and all({"annotation_kind", "label", "text", "t_ns", "mono_ns", "id",
                                    "actor"} <= set(e) for e in notes)

    # after the flight: radar-io annotate
    t_cli = made[0]["t_ns"] + 200_000_000
    assert cli_main(["annotate", str(rec_path), "--kind", "marker", "--label", "CLI",
                     "--t-ns", str(t_cli), "--actor", "analyst"]) == 0

    # the report: the test-point table with DY / DZ statistics over TP1's frames
    from radar_io.analysis.flight_digest import digest_recording
    from radar_io.analysis.report import build_report, render_html
    from radar_io.coordinates.reference_path import load_path
    from radar_io.coordinates.transforms import load_site

    site = load_site(spec_dir() / "sites" / "demo.toml")
    d = digest_recording(rec_path, site=site, ref_path=load_path(PATH))
    (tp,) = d.test_points()
    assert tp["label"] == "TP1" and tp["text"] == "level 600 m"
    assert tp["to_s"] - tp["from_s"] == pytest.approx(2.0, abs=0.3)
    assert tp["samples"] > 100 and tp["dy_rms_m"] >= 0 and tp["dy_max_abs_m"] >= tp["dy_rms_m"]
    assert [e["label"] for e in d.annotations] == ["TP1", "CLI", "", "late", "TP1"]
    rep = build_report(d)
    html = render_html(rep)
    rep.close()
    assert "Test points (1)" in html and "<td>TP1</td>" in html and "<td>analyst</td>" in html

    # the archive: the events table beside the frames, joined in DuckDB
    import duckdb

    from radar_io.analysis.archive import archive_recording

    out = tmp_path / "archive"
    res = archive_recording(rec_path, out, site=site, reference_path=load_path(PATH))
    assert (res.path.parent / "events.jsonl").is_file()
    con = duckdb.connect()
    got = con.sql(f"""
        SELECT e.recording, e.label, e.annotation_kind, e.actor
        FROM read_json('{out}/**/events.jsonl', hive_partitioning = true,
                       format = 'newline_delimited') AS e
        WHERE e.kind = 'annotation' ORDER BY e.t_ns""").fetchall()
    assert got == [(rec, "TP1", "test_point_start", "op"), (rec, "CLI", "marker", "analyst"),
                   (rec, "", "marker", "op"), (rec, "late", "note", "op"),
                   (rec, "TP1", "test_point_end", "op")]
    frames = con.sql(f"SELECT count(*) FROM read_parquet('{out}/**/*.parquet', "
                     "hive_partitioning = true)").fetchall()[0][0]
    assert frames == d.n_frames  # the *.parquet glob still sees the frames only

    # Chapter 10: the annotations as recording events, defined in the TMATS
    pytest.importorskip("chapter10", reason="pychapter10 is not installed (README test "
                        "command: pip install --no-deps pychapter10 bitstring)")
    import struct

    from chapter10 import C10

    ch10 = tmp_path / "rec.ch10"
    assert cli_main(["export", str(rec_path), "-o", str(ch10)]) == 0
    tmats, numbers = "", []
    raw = ch10.read_bytes()
    off = 0
    for p in C10(str(ch10)):  # pychapter10 reads the packets; the entries from their bytes
        if p.data_type == 0x01:
            tmats = p.data.decode("ascii")
        elif p.data_type == 0x02:
            body = raw[off + 24:off + p.packet_length - 4]
            n = struct.unpack("<I", body[:4])[0] & 0xFFF
            numbers += [struct.unpack("<I", body[12 + 12 * k:16 + 12 * k])[0] & 0xFFF
                        for k in range(n)]
        off += p.packet_length
    names = {int(code.rsplit("-", 1)[1]): value for code, _, value in
             (x.strip().partition(":") for x in tmats.split(";"))
             if code.startswith("R-1\\EV\\ID-")}
    got = sorted(names[n] for n in numbers if names.get(n) not in ("SYNC", "GO_ON", "GO_OFF"))
    assert got == ["CLI", "TP1", "TP1", "late", "marker"], got
    assert "test_point_start: level 600 m" in tmats
