"""The service's wall clock stepped ±1 h by libfaketime during a 1 kHz pty run (issue 20,
figure 1); the monotonic clock is not faked (``FAKETIME_DONT_FAKE_MONOTONIC=1``), and a
preloaded shim (``preload/mono_sleep.c``) passes monotonic sleeps through, which
libfaketime 0.9.10 breaks with that setting (its issue 426).

Shown: each GO recording has 2.0 ± 0.1 s of pre-roll; 0 frames lost; the stepped recording
replays in its monotonic duration ± 2 % and a seek to t lands within ± 20 ms of t; a limit
alarm with ``for_s`` raises between ``for_s`` and ``for_s`` + 0.5 s after the first
violating frame although the clock steps right after it; the CRC-rate alarm rises within
2 s of a CRC burst and stays raised to its end across a step; each step is a
``clock_step`` event with its size in the recording's events and the last one on
``/api/status``.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import independent
import pytest
from conftest import require_program

from radar_io.benchmarks.service_load import Pty, ServeProcess
from radar_io.sources.replay import ReplaySource

from .preload import LIBFAKETIME, compile_shim
from .test_live_pty import wait_for
from .test_slow_disk import Paced, frames_with_chunks

GO, IDLE = 0x0005, 0x0004
RATE_HZ = 1000
FOR_S = 1.0
#: (time into the run, s) → the faked wall-clock offset from then on (s)
STEPS = {1.5: -3600, 4.0: 0, 5.1: -3600, 9.0: 0, 12.0: -3600}
GO_PERIODS = ((3.0, 11.0), (14.0, 15.5))
VIOLATION = (5.0, 7.5)   #: sr_m above its limit
CRC_BURST = (8.0, 10.0)  #: every 4th frame with a bad CRC
END_S = 16.0
STEP_AFTER_S = 5.1 - VIOLATION[0]  #: the step right after the first violating frame


def _stream() -> tuple[list[bytes], set[int]]:
    """The frames (SEQ = index) and the indices sent with a bad CRC."""
    frames, bad = [], set()
    for k in range(int(END_S * RATE_HZ)):
        t = k / RATE_HZ
        go = any(a <= t < b for a, b in GO_PERIODS)
        sr = 6000 if VIOLATION[0] <= t < VIOLATION[1] else 1000
        crc = None
        if CRC_BURST[0] <= t < CRC_BURST[1] and k % 4 == 0:
            crc = 0  # not the frame's CRC
            bad.add(k)
        frames.append(independent.frame(seq=k, tod=k, sr=sr, sts=GO if go else IDLE, crc=crc))
    return frames, bad


def _set_offset(path: Path, offset_s: int) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(f"{offset_s:+d}\n")
    os.replace(tmp, path)  # libfaketime never reads a half-written file


@pytest.mark.slow
def test_wall_clock_steps_of_an_hour_change_no_duration(tmp_path):
    require_program("faketime")
    if not LIBFAKETIME.exists():
        pytest.skip(f"{LIBFAKETIME} missing (Debian package faketime)")
    shim = compile_shim("mono_sleep", tmp_path, require_program("cc", "gcc"))
    stamp = tmp_path / "faketime"
    _set_offset(stamp, 0)
    cfg = tmp_path / "serve.toml"
    cfg.write_text(f'auto_record = "go"\n[[alarms]]\ncolumn = "sr_m"\nmax = 5000.0\n'
                   f"for_s = {FOR_S}\n")
    frames, bad = _stream()
    pty = Pty()
    data = tmp_path / "data"
    svc = ServeProcess(pty.path, data, extra=("--config", str(cfg)), env={
        "LD_PRELOAD": f"{shim} {LIBFAKETIME}", "FAKETIME_DONT_FAKE_MONOTONIC": "1",
        "FAKETIME_TIMESTAMP_FILE": str(stamp), "FAKETIME_NO_CACHE": "1"})
    paced = Paced(pty, frames, RATE_HZ,
                  at={int(t * RATE_HZ): (lambda o=o: _set_offset(stamp, o))
                      for t, o in STEPS.items()})
    try:
        svc.wait_ready()
        paced.start().join()
        st = wait_for(lambda: (s := svc.get("/api/status"))["frames"] == len(frames) - len(bad)
                      and s["recording"] is None and s, what="every frame decoded")
        wait_for(lambda: svc.get("/api/status")["storage"]["buffer"]["pending_bytes"] == 0,
                 what="all written")
    finally:
        err = svc.stop()
        pty.close()
    sent = paced.sent_mono
    assert st["crc_errors"] >= len(bad) and st["processing_errors"] == 0, err
    recs = sorted((data / "recordings").glob("*.rdrlog"))
    assert len(recs) == 2, err
    figures = [(f"{len(frames) - len(bad)} good frames sent (and {len(bad)} with a bad CRC), "
                f"{st['frames']} decoded; both recordings hold every good frame of their span")]
    # 0 frames lost; each recording: 2.0 ± 0.1 s of pre-roll before its GO edge
    for p, (go_s, end_s) in zip(recs, GO_PERIODS, strict=True):
        got = frames_with_chunks(p)
        seqs = [s for s, _, _ in got]
        first, last = seqs[0], seqs[-1]
        assert seqs == [k for k in range(first, last + 1) if k not in bad]
        assert last >= int(end_s * RATE_HZ) - 1
        rise = next(mono for s, mono, _ in got if s == int(go_s * RATE_HZ))
        preroll_s = (rise - got[0][1]) / 1e9
        figures.append(f"{p.stem}: pre-roll {preroll_s:.3f} s")
        assert abs(preroll_s - 2.0) <= 0.1, preroll_s
    # the stepped recording replays in its monotonic duration ± 2 %, seeks land ± 20 ms
    r1 = recs[0]
    got = frames_with_chunks(r1)
    t_first = sent[got[0][0]]  # the time its first frame was written
    ctl = ReplaySource(r1, 1.0)
    ctl.open()
    try:
        t0 = None
        while not ctl.finished:
            if ctl.read(0.05) and t0 is None:
                t0 = time.monotonic()
        played_s = time.monotonic() - t0  # type: ignore[operator]
        seek_err_ms = []
        for pos_s in (1.0, 2.5, 4.5, 6.0, 7.5):  # after the steps at 4.0, 5.1 and 9.0 s
            ctl.seek(pos_s)
            ctl.pause()
            ctl.step()
            chunk = b""
            while not chunk:
                chunk = ctl.read(0.05)
            seq = int.from_bytes(chunk[chunk.index(b"\xeb\x90") + 2:][:2], "big")
            seek_err_ms.append((sent[seq] - t_first - pos_s) * 1e3)
            ctl.resume()
    finally:
        ctl.close()
    figures.append(f"replay of {r1.stem}: {played_s:.3f} s for {ctl.duration_s:.3f} s recorded "
                   f"({(played_s / ctl.duration_s - 1) * 100:+.2f} %); seek errors "
                   f"{', '.join(f'{e:+.1f}' for e in seek_err_ms)} ms")
    assert abs(played_s / ctl.duration_s - 1) <= 0.02
    assert all(abs(e) <= 20 for e in seek_err_ms), seek_err_ms
    # the recording's events: the steps, the limit alarm, the CRC-rate alarm
    events = [json.loads(x) for x in r1.with_suffix(".events.jsonl").read_text().splitlines()]
    steps = [e["step_s"] for e in events if e["kind"] == "clock_step"]
    figures.append(f"clock_step events in {r1.stem}: {steps}")
    assert len(steps) == 3
    assert [round(s) for s in steps] == [3600, -3600, 3600]
    assert all(abs(abs(s) - 3600) < 0.05 for s in steps)
    alarms = [e for e in events if e["kind"] == "alarm"]
    limit = [e for e in alarms if e["id"] == "limit:sr_m"]
    raise_s = (limit[0]["mono_ns"] / 1e9) - sent[int(VIOLATION[0] * RATE_HZ)]
    figures.append(f"limit alarm (for_s {FOR_S}) raised {raise_s:.3f} s after the first "
                   f"violating frame (clock stepped -1 h {STEP_AFTER_S:.1f} s after it)")
    assert limit[0]["action"] == "raise" and FOR_S <= raise_s <= FOR_S + 0.5
    crc = [e for e in alarms if e["id"] == "crc_rate"]
    crc_raise_s = crc[0]["mono_ns"] / 1e9 - sent[int(CRC_BURST[0] * RATE_HZ)]
    cleared = [e for e in crc if e["action"] == "clear"]
    burst_end = sent[int(CRC_BURST[1] * RATE_HZ) - 1]
    figures.append(f"CRC-rate alarm raised {crc_raise_s:.3f} s into the burst, "
                   + (f"cleared {cleared[0]['mono_ns'] / 1e9 - burst_end:.2f} s after its end"
                      if cleared else "still raised when the recording closed"))
    assert crc[0]["action"] == "raise" and 0 < crc_raise_s <= 2.0
    assert all(e["mono_ns"] / 1e9 > burst_end for e in cleared)  # raised across the step at 9 s
    # the status: the last step (size, both clocks, count)
    last = st["clock"]["last_step"]
    figures.append(f"/api/status clock: {st['clock']}")
    assert st["clock"]["steps"] == len(STEPS) and last["count"] == len(STEPS)
    assert abs(last["step_s"] + 3600) < 0.05
    assert abs(last["mono_ns"] / 1e9 - sent[int(12.0 * RATE_HZ)]) < 0.1
    print("\nwall clock stepped ±1 h during a 1 kHz pty run:\n  " + "\n  ".join(figures))

