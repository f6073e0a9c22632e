"""Flight report: figures and tables from a simulated recording, HTML opened offline in
headless Chromium, PDF pages, progress only on a terminal, one-line errors."""

from __future__ import annotations

import base64
import json
import os
import re
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, require_program, run_cli

ARTIFACTS = Path(os.environ.get("RADAR_IO_ARTIFACTS", ROOT / "artifacts"))
DEMO_PATH = ROOT / "firmware_specs" / "paths" / "demo_track_radar.toml"


@pytest.fixture(scope="module")
def flight(tmp_path_factory) -> Path:
    """40 s of the demo flight 20 m above the demo path, with bit flips (CRC errors)."""
    out = tmp_path_factory.mktemp("rep") / "flight.rdrlog"
    r = run_cli("simulate", "--duration-s", "40", "--height-m", "620", "--flip-rate", "2e-5",
                "--sync-every-s", "2", "--seed", "7", "-o", str(out))
    assert r.returncode == 0, r.stderr.decode()
    return out


def _payload(path: Path) -> bytes:
    from radar_io.recording.rdrlog import RecordingReader

    with RecordingReader(path) as r:
        return b"".join(c.data for c in r)


def test_digest_summary_matches_an_independent_decode(flight):
    from radar_io.analysis.flight_digest import digest_recording
    from radar_io.coordinates.reference_path import load_path
    from radar_io.decoding.decoders import decode_bytes

    d = digest_recording(flight, ref_path=load_path(DEMO_PATH), piece_bytes=4096)
    b = decode_bytes(_payload(flight))
    s = d.summary()
    assert s["frames"] == len(b) and s["crc_errors"] == b.stats["crc_errors"] > 0
    assert s["seq_gaps"] == b.stats["seq_gaps"]
    sync = b["sync"].astype(bool)
    edges = int(np.sum(sync[1:] & ~sync[:-1]) + sync[0])
    assert s["sync_events"] == edges >= 15
    assert s["rx_good_fraction"] == pytest.approx(float(np.mean(b["rx_good"])))
    assert s["go_time_s"] == pytest.approx(float(np.sum(b["go"])) * 1e-3, rel=1e-6)
    assert s["duration_s"] == pytest.approx(40.0, abs=0.1)
    # the CRC timeline ends at the total and never decreases
    assert d.counter_crc[-1] == b.stats["crc_errors"] and np.all(np.diff(d.counter_crc) >= 0)
    # flown 20 m above the path: DZ RMS and max near 20 m on the one straight leg
    legs = d.legs()
    assert [g["leg"] for g in legs] == [0]
    assert legs[0]["dz_rms_m"] == pytest.approx(20.0, abs=3.0)
    assert legs[0]["dz_max_abs_m"] >= legs[0]["dz_rms_m"]
    assert legs[0]["dy_rms_m"] < 10.0
    ev = d.sync_events()
    i = int(np.flatnonzero(sync[1:] & ~sync[:-1])[0] + 1)
    assert ev[0]["seq"] == int(b["seq"][i]) and ev[0]["tod_s"] == pytest.approx(float(b["tod_s"][i]))


def test_calibration_biases_move_the_track(flight):
    """--calibration: a +0.05 deg elevation bias raises every valid point by SR·0.05 deg."""
    from radar_io.analysis.flight_digest import digest_recording
    from radar_io.decoding.biases import Calibration

    a = digest_recording(flight)
    b = digest_recording(flight, calibration=Calibration(del_deg=0.05, id="t"))
    ok = np.isfinite(a.columns["h_m"])
    sr = a.columns["sr_m"][ok] + a.columns["dsr_m"][ok]
    dh = b.columns["h_m"][ok] - a.columns["h_m"][ok]
    assert np.allclose(dh, sr * np.deg2rad(0.05), rtol=0.01)
    assert b.summary()["frames"] == a.summary()["frames"]


def test_alarm_events_of_the_recording_are_tabled(flight, tmp_path):
    import shutil

    from radar_io.analysis.flight_digest import digest_recording
    from radar_io.analysis.report import build_report, render_html
    from radar_io.recording.recorder import Recorder
    from radar_io.service.alarms import AlarmEngine, EventLog, LimitRule
    from radar_io.wirespec.frame import load_spec

    rec = tmp_path / "x.rdrlog"
    shutil.copy(flight, rec)
    # the service's engine and event log (through a recorder), fed 3 samples: raise at SEQ
    # 7, clear at SEQ 9; the recording's events file then sits beside the flight
    recorder = Recorder(tmp_path / "svc", load_spec(), None, "test", auto="manual")
    rid = recorder.start()
    eng = AlarmEngine([LimitRule("hi", "height high", "h_m", None, 610.0)], {},
                      on_event=EventLog(recorder))
    eng.feed([{"h_m": v, "seq": s, "t_ns": 1_800_000_000_000_000_000 + s * 10**6}
              for v, s in ((600.0, 6), (612.5, 7), (611.0, 8), (605.0, 9))])
    recorder.close()
    shutil.copy(recorder.dir / f"{rid}.events.jsonl", tmp_path / "x.events.jsonl")
    d = digest_recording(rec)
    assert [(e["action"], e["seq"]) for e in d.alarm_events] == [("raise", 7), ("clear", 9)]
    rep = build_report(d)
    try:
        text = render_html(rep)
    finally:
        rep.close()
    assert "Alarm events (2)" in text
    assert "<td>2027-01-15T08:00:00.007Z</td><td>7</td><td>raise</td><td>height high</td>" \
           "<td>h_m</td><td>612.5</td><td>610</td>" in text


def _html_report(flight: Path, tmp: Path) -> Path:
    out = tmp / "report.html"
    r = run_cli("report", str(flight), "--site", "demo", "--path", str(DEMO_PATH), "-o", str(out))
    assert r.returncode == 0, r.stderr.decode()
    assert b"\r" not in r.stderr  # stderr is a pipe: no progress line, just the summary
    assert b"8 figures" in r.stderr
    return out


def test_html_is_self_contained_with_figures_and_tables(flight, tmp_path):
    text = _html_report(flight, tmp_path).read_text(encoding="utf-8")
    assert "<script" not in text and not re.search(r"(src|href)=\"(https?:)?//", text)
    imgs = re.findall(r'src="data:image/png;base64,([^"]+)"', text)
    assert len(imgs) == 8  # plan, height, DY/DZ, SR/EL/AZ, link health, 3 BET
    assert "Best estimate of trajectory" in text and "BET outliers (" in text
    for b64 in imgs:
        png = base64.b64decode(b64)
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    assert "Deviation per leg" in text and "Sync events (" in text
    from radar_io.decoding.decoders import decode_bytes

    frames = len(decode_bytes(_payload(flight)))
    assert f"<td>frames</td><td>{frames}</td>" in text


class _Chrome:
    """Headless Chromium (tests/service/cdp.py) keeping the console and exception events."""

    def __init__(self, profile: Path) -> None:
        from service.cdp import Chrome

        self.c = Chrome(profile)
        self.events: list[dict] = []
        orig = self.c.ws.recv

        def recv(timeout=None):
            while True:
                raw = orig(timeout=timeout)
                msg = json.loads(raw)
                if "method" in msg:
                    self.events.append(msg)
                return raw

        self.c.ws.recv = recv


def test_html_opens_offline_in_chromium_without_console_errors(flight, tmp_path):
    require_program("chromium", "chromium-browser", "google-chrome")
    html = _html_report(flight, tmp_path)
    ch = _Chrome(tmp_path / "profile")
    try:
        c = ch.c
        c.call("Runtime.enable")
        c.call("Log.enable")
        c.call("Page.enable")
        c.call("Network.enable")
        # offline: any network request would fail and be reported
        c.call("Network.emulateNetworkConditions", offline=True, latency=0,
               downloadThroughput=-1, uploadThroughput=-1)
        c.call("Page.navigate", url=html.as_uri())
        c.wait_for("document.readyState === 'complete'")
        n = c.wait_for("Array.from(document.images).every(i => i.complete && i.naturalWidth > 0)"
                       " && document.images.length")
        assert n == 8
        widths = c.eval("Array.from(document.images).map(i => i.naturalWidth)")
        assert all(w >= 600 for w in widths)
        c.eval("1")  # drain pending events
        bad = [e for e in ch.events if e["method"] == "Runtime.exceptionThrown"
               or (e["method"] == "Runtime.consoleAPICalled" and e["params"]["type"] == "error")
               or (e["method"] == "Log.entryAdded" and e["params"]["entry"]["level"] == "error")
               or e["method"] == "Network.loadingFailed"]
        assert bad == []
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        c.screenshot(ARTIFACTS / "report_html.png")
        assert (ARTIFACTS / "report_html.png").stat().st_size > 10000
        c.eval("document.querySelector('figure').scrollIntoView(), true")
        c.screenshot(ARTIFACTS / "report_html_plan.png")
    finally:
        ch.c.close()


def _pdf_pages(data: bytes) -> int:
    try:
        from pypdf import PdfReader
    except ImportError:
        return len(re.findall(rb"/Type\s*/Page[^s]", data))
    import io

    return len(PdfReader(io.BytesIO(data)).pages)


def test_pdf_pages_and_figures(flight, tmp_path):
    from radar_io.analysis.flight_digest import digest_recording

    out = tmp_path / "report.pdf"
    r = run_cli("report", str(flight), "--path", str(DEMO_PATH), "-o", str(out))
    assert r.returncode == 0, r.stderr.decode()
    data = out.read_bytes()
    assert data.startswith(b"%PDF-") and data.rstrip().endswith(b"%%EOF")
    n_sync = len(digest_recording(flight).sync_events())
    # summary + legs + sync-event pages (40 rows each) + BET table and outliers + 8 figures
    expected = 1 + 1 + -(-n_sync // 40) + 2 + 8
    assert _pdf_pages(data) == expected
    assert f"{expected} pages".encode() in r.stderr
    # without a path: no DY/DZ figure, no leg table
    out2 = tmp_path / "nopath.pdf"
    r = run_cli("report", str(flight), "-o", str(out2), "-q")
    assert r.returncode == 0 and r.stderr == b""
    assert _pdf_pages(out2.read_bytes()) == expected - 2


def test_airdata_adds_the_pressure_altitude_figure(tmp_path):
    """A radar recording and an airborne CAN log of the same simulated flight: the report's
    PA − H statistics equal those of `radar-io align`, and a last figure appears."""
    from radar_io.analysis.flight_digest import digest_recording
    from radar_io.analysis.report import build_report

    rec, log = tmp_path / "r.rdrlog", tmp_path / "air.asc"
    assert run_cli("simulate", "-o", str(rec), "--duration-s", "20", "--sync-every-s", "1.5",
                   "-q").returncode == 0
    r = run_cli("can-log", "--interface", "virtual", "--channel", "report", "-o", str(log),
                "--simulate", "--duration-s", "20", "--sync-every-s", "1.5", "-q")
    assert r.returncode == 0, r.stderr.decode()
    r = run_cli("align", str(rec), str(log))
    assert r.returncode == 0, r.stderr.decode()
    want = json.loads(r.stdout)["altitude"]["pressure_altitude_minus_radar_h_m"]
    rep = build_report(digest_recording(rec), airdata=str(log))
    try:
        assert rep.airdata["samples"] == want["n"] > 100
        assert rep.airdata["mean_m"] == pytest.approx(want["mean"], abs=1e-9)
        assert [t for t, _ in rep.figures][-1] == "Pressure altitude − radar height"
        assert len(rep.figures) == 8
    finally:
        rep.close()
    out = tmp_path / "air.pdf"
    r = run_cli("report", str(rec), "--airdata", str(log), "-o", str(out))
    assert r.returncode == 0, r.stderr.decode()
    assert b"8 figures" in r.stderr  # plan, height, SR/EL/AZ, link, 3 BET, air data (no DY/DZ)


@pytest.mark.parametrize("args, needle", [
    (["nope.rdrlog", "-o", "x.html"], "recording not found: nope.rdrlog"),
    (["{flight}", "-o", "x.docx"], "report format must be html or pdf"),
    (["{flight}", "-o", "x.html", "--site", "atlantis"], "site 'atlantis': no such file"),
    (["{garbage}", "-o", "x.html"], "no RDR1 frames found"),
])
def test_bad_input_is_one_line(flight, tmp_path, args, needle):
    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(bytes(range(7, 250)) * 40)
    argv = [a.format(flight=flight, garbage=garbage) for a in args]
    argv = [str(tmp_path / a) if a.startswith("x.") else a for a in argv]
    r = run_cli("report", *argv)
    err = r.stderr.decode().strip()
    assert r.returncode == 2 and len(err.splitlines()) == 1 and needle in err, err


def test_progress_only_on_a_terminal():
    import io
    import pty

    from radar_io.cli.progress import Progress

    buf = io.StringIO()
    p = Progress("job", total=100, stream=buf, interval_s=0.0)
    for k in range(0, 101, 10):
        p.update(k)
    p.close("done")
    assert buf.getvalue() == "job: done\n"  # a log: summary only, no carriage returns
    master, slave = pty.openpty()
    try:
        with os.fdopen(slave, "w", closefd=True) as tty:
            p = Progress("job", total=100, stream=tty, interval_s=0.0)
            p.update(50)
            p.close("done")
        time.sleep(0.05)
        out = os.read(master, 4096)
    finally:
        os.close(master)
    assert out.startswith(b"\rjob:") and b"50.0 %" in out and out.endswith(b"job: done\r\n")


def test_thinned_rows_and_flag_minima_match_the_full_decode(flight):
    """A small row budget forces the stride to double many times across blocks: the rows are
    still every stride-th frame, GO / RX GOOD minima and SEQ jumps cover every frame, and
    the statistics equal those of the whole decode."""
    from radar_io.analysis.flight_digest import digest_recording
    from radar_io.decoding.decoders import decode_bytes

    b = decode_bytes(_payload(flight))
    n = len(b)
    d = digest_recording(flight, piece_bytes=3000, max_rows=100)
    assert d.frames == n and 50 <= d.columns["t_s"].size <= 100
    s = d.stride
    assert s > 1 and d.columns["t_s"].size == -(-n // s)
    for k in ("seq", "sr_m", "go", "rx_good"):
        assert np.array_equal(d.columns[k], np.asarray(b[k])[::s], equal_nan=True), k
    for k in ("go", "rx_good"):
        want = np.minimum.reduceat(np.asarray(b[k]).astype(np.int8), np.arange(0, n, s))
        assert np.array_equal(d.flag_min[k], want), k
    seq = np.asarray(b["seq"]).astype(np.int64)
    jumps = np.flatnonzero(np.diff(seq) != 1) + 1
    assert jumps.size > 0
    assert np.array_equal(np.flatnonzero(np.isfinite(d.seq_jump_t_s)), np.unique(jumps // s))
    full = digest_recording(flight)
    assert d.summary() == full.summary() and d.sync_events() == full.sync_events()
    assert d.frame_period_s == full.frame_period_s == pytest.approx(1e-3)


def test_bet_page_smooths_a_decimated_set_against_the_simulator_truth(flight):
    """The BET page in bounded memory: at most max_rows measurements (every stride-th
    frame), the smoothed ground speed and vertical speed of the simulated level flight
    (70 m/s, 620 m) inside their ±3σ, NIS mean near its χ²₃ value or below (the site σ
    are TR-861's, larger than the simulator's noise), and the tables."""
    from radar_io.analysis import bet_page
    from radar_io.analysis.flight_digest import digest_recording

    d = digest_recording(flight)
    p = bet_page.build_bet(d, max_rows=2000)
    assert p is not None and p.stride == -(-d.n_frames // 2000) and len(p.track) <= 2000
    k = p.track
    late = (p.t_s > 5.0) & np.isfinite(np.asarray(k["gs_mps"]))
    gs, vs = np.asarray(k["gs_mps"])[late], np.asarray(k["vs_mps"])[late]
    s_vx = np.asarray(k["vx_sigma_mps"], dtype=float)[late]
    s_vh = np.asarray(k["vh_sigma_mps"], dtype=float)[late]
    assert np.mean(np.abs(gs - 70.0) <= 3 * s_vx) > 0.95
    assert np.mean(np.abs(vs) <= 3 * s_vh) > 0.95
    assert np.median(np.abs(gs - 70.0)) < 0.5
    assert 0.05 < float(p.summary["tracking.nis_mean"]) < 4.0
    for c, lim in (("sr_m", 5.0), ("el_deg", 0.02), ("az_deg", 0.02)):
        assert p.summary[f"residual_{c}_rms"] < lim, c
    rows = dict(bet_page.summary_rows(p))
    assert rows["measurements smoothed"].startswith(f"{len(p.track)} (1 frame in {p.stride})")
    full = bet_page.build_bet(d)  # the default: every frame of a 40-s recording
    assert full is not None and full.stride == 1 and len(full.track) == d.n_frames
