"""Calibration sets survive power cuts and concurrent writers: written through the atomic
file (unique temporary name, fsync of the file and of the directory, rename), every applied
version kept, and an unreadable ``active.json`` at start reported instead of stopping the
service (which goes on acquiring and recording without biases)."""

from __future__ import annotations

import json
import os
import stat
import threading
import time
import urllib.request

import pytest

from radar_io.benchmarks.service_load import ServeProcess
from radar_io.decoding.biases import Calibration, load_calibration, save_calibration
from radar_io.service.calibrations import CalibrationStore

from .test_serve_config import serve

TOKEN = "cal-token"


def cal(name: str, dsr_m: float) -> Calibration:
    return Calibration(dsr_m=dsr_m, del_deg=0.01, daz_deg=-0.02, id=name,
                       created_utc="2026-11-25T12:00:00Z")


def test_concurrent_saves_of_one_file_never_share_a_temporary_file(tmp_path):
    """Two writers replacing the same file 200 times each: every save succeeds, the file
    is always one whole set, and no temporary file is left."""
    target = tmp_path / "active.json"
    sets = [cal("a", 1.0), cal("b", 2.0)]
    errors: list[BaseException] = []
    seen: list[Calibration] = []
    stop = threading.Event()

    def writer(c: Calibration) -> None:
        try:
            for _ in range(200):
                save_calibration(c, target)
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    def reader() -> None:
        while not stop.is_set():
            if target.exists():
                seen.append(load_calibration(target))  # raises on a half-written file

    threads = [threading.Thread(target=writer, args=(c,)) for c in sets]
    r = threading.Thread(target=reader)
    r.start()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    stop.set()
    r.join()
    assert errors == []
    assert seen and {c.id for c in seen} <= {"a", "b"}
    assert load_calibration(target) in sets
    assert [p.name for p in tmp_path.iterdir()] == ["active.json"]


def test_a_save_fsyncs_the_file_and_then_its_directory(tmp_path, monkeypatch):
    synced: list[str] = []
    real_fsync = os.fsync

    def spy(fd: int) -> None:
        mode = os.fstat(fd).st_mode
        synced.append("dir" if stat.S_ISDIR(mode) else "file")
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", spy)
    save_calibration(cal("a", 1.0), tmp_path / "a.json")
    assert synced == ["file", "dir"]
    assert load_calibration(tmp_path / "a.json") == cal("a", 1.0)


@pytest.mark.parametrize("content", [b"", b'{"format": "radar_io-calibration/1", "id": "x", "bi',
                                     b"\x00" * 64, b"[1, 2]"])
def test_an_unreadable_active_set_is_reported_with_the_last_good_one(tmp_path, content):
    store = CalibrationStore(tmp_path)
    applied: list[Calibration] = []
    store.save(cal("old", 1.0), applied.append)
    store.save(cal("new", 2.0), applied.append)
    assert applied == [cal("old", 1.0), cal("new", 2.0)]
    assert [p.name.split("@")[0] for p in store.history()] == ["new", "old"]
    (tmp_path / "active.json").write_bytes(content)  # a power cut, a truncation, a bad edit

    again = CalibrationStore(tmp_path)
    assert again.load_active() == Calibration()  # no biases
    assert again.error is not None and str(tmp_path / "active.json") in again.error
    assert "\n" not in again.error
    assert again.last_good is not None
    assert again.last_good["set"]["id"] == "new" and "history" in again.last_good["file"]
    # the operator applies it: the error is gone and active.json is whole again
    again.save(Calibration.from_dict(again.last_good["set"]), applied.append)
    assert again.error is None and again.last_good is None
    assert load_calibration(tmp_path / "active.json") == cal("new", 2.0)
    assert len(again.history()) == 3


def test_an_unreadable_newest_version_is_skipped_for_the_last_good(tmp_path):
    store = CalibrationStore(tmp_path)
    store.save(cal("old", 1.0), lambda c: None)
    store.save(cal("new", 2.0), lambda c: None)
    store.history()[0].write_bytes(b"")
    (tmp_path / "active.json").write_bytes(b"")
    again = CalibrationStore(tmp_path)
    again.load_active()
    assert again.last_good is not None and again.last_good["set"]["id"] == "old"


def _put(base: str, doc: dict) -> tuple[int, dict]:
    req = urllib.request.Request(base + "/api/calibration", data=json.dumps(doc).encode(),
                                 method="PUT", headers={"Content-Type": "application/json",
                                                        "Authorization": f"Bearer {TOKEN}"})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def test_serve_starts_without_an_empty_active_set_and_says_so(tmp_path):
    """A zero-length active.json (a power cut during a write by an older version):
    ``serve`` starts, acquires and records without biases; /api/status and the alarms say
    why and offer the last good set; applying it clears the alarm. Two PUTs at once both
    land whole."""
    data = tmp_path / "data"
    store = CalibrationStore(data / "calibrations")
    store.save(cal("flight-6", 3.0), lambda c: None)
    (data / "calibrations" / "active.json").write_bytes(b"")
    with ServeProcess("sim://?go_delay_s=0", data, extra=("--auto-record", "always"),
                      env={"RADAR_IO_TOKEN": TOKEN}) as svc:
        st = svc.get("/api/status")
        assert st["calibration"] == "none"
        assert "active.json" in st["calibration_error"] and "empty" in st["calibration_error"]
        good = st["calibration_last_good"]
        assert good["set"]["id"] == "flight-6" and good["set"]["biases"]["dsr_m"] == 3.0
        deadline = time.monotonic() + 20
        while True:  # data flows and is recorded
            st = svc.get("/api/status")
            alarms = {a["id"] for a in svc.get("/api/alarms")["alarms"]}
            if st["frames"] > 100 and st["recording"] and "calibration_unreadable" in alarms:
                break
            assert time.monotonic() < deadline, (st, alarms)
            time.sleep(0.1)
        rec = data / "recordings" / f"{st['recording']}.rdrlog"
        assert rec.stat().st_size > 1000
        # concurrent PUTs of two sets: both answered, both files whole
        results: list[tuple[int, dict]] = []
        docs = [cal("a", 1.0).to_dict(), cal("b", 2.0).to_dict()]
        threads = [threading.Thread(target=lambda d=d: results.append(_put(svc.base, d)))
                   for d in docs]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert sorted(code for code, _ in results) == [200, 200], results
        for name, dsr in (("a", 1.0), ("b", 2.0)):
            assert load_calibration(data / "calibrations" / f"{name}.json").dsr_m == dsr
        active = load_calibration(data / "calibrations" / "active.json")
        st = svc.get("/api/status")
        assert st["calibration"] == active.id and active.id in ("a", "b")
        assert st["calibration_error"] is None and st["calibration_last_good"] is None
        deadline = time.monotonic() + 5
        while "calibration_unreadable" in {a["id"] for a in svc.get("/api/alarms")["alarms"]}:
            assert time.monotonic() < deadline
            time.sleep(0.1)
    assert not [p for p in (data / "calibrations").rglob("*") if p.name.endswith(".part")]
    assert len(list((data / "calibrations" / "history").iterdir())) == 3


def test_an_explicit_bad_calibration_file_is_still_refused(tmp_path):
    bad = tmp_path / "cal.json"
    bad.write_bytes(b"")
    r = serve(tmp_path, "--calibration", str(bad))
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(bad) in lines[0] and "empty" in lines[0], r.stderr
