"""``radar-io doctor``: the source check against sim://, a pty that carries real frames, a
silent pty and a missing device; the FTDI latency timer; the exit code."""

from __future__ import annotations

import os
import re
import threading

import pytest
from conftest import run_cli

from radar_io.cli import doctor


def _lines(out: bytes) -> list[str]:
    return out.decode().splitlines()


def _fails(lines: list[str]) -> int:
    return sum(ln.startswith("FAIL") for ln in lines)


def test_doctor_against_sim_passes_the_source_check(tmp_path):
    r = run_cli("doctor", "--source", "sim://", "--data-dir", str(tmp_path / "data"),
                "--timeout-s", "5")
    lines = _lines(r.stdout)
    src = [ln for ln in lines if ln.startswith(("OK", "WARN", "FAIL")) and "source:" in ln]
    assert len(src) == 1 and src[0].startswith("OK    source: sim://"), lines
    assert re.search(r"sim://: \d+ frames in \d+ bytes", src[0])
    names = [ln.split(":")[0].split()[-1] for ln in lines if not ln.startswith(" ")]
    assert {"permission", "disk", "source", "clock"} <= set(names)
    # every non-OK line is followed by its one-line fix
    for k, ln in enumerate(lines):
        if ln.startswith(("WARN", "FAIL")):
            assert lines[k + 1].startswith("      fix: ")
    assert r.returncode == (1 if _fails(lines) else 0)


def test_doctor_with_a_missing_device_fails_with_the_fix(tmp_path):
    dev = tmp_path / "ttyUSB9"
    r = run_cli("doctor", "--source", str(dev), "--data-dir", str(tmp_path), "--timeout-s", "1")
    lines = _lines(r.stdout)
    k = next(i for i, ln in enumerate(lines) if "source:" in ln)
    assert lines[k].startswith(f"FAIL  source: cannot open {dev}")
    assert lines[k + 1].startswith("      fix: check the cable and the device name")
    assert r.returncode == 1
    assert "FAIL" in r.stderr.decode().splitlines()[-1]


@pytest.mark.slow
def test_source_check_on_a_pty(spec):
    """A real terminal pair: silent, then carrying garbage, then simulated RDR1 frames."""
    import pty

    from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig

    master, slave = pty.openpty()
    dev = os.ttyname(slave)
    try:
        c = doctor.check_source(dev, timeout_s=0.5, spec=spec)
        assert c.level == "FAIL" and "no bytes" in c.message and "radar is on" in c.fix

        def feed(data: bytes) -> None:
            os.write(master, data)

        t = threading.Timer(0.2, feed, args=(bytes(range(1, 200)),))
        t.start()
        c = doctor.check_source(dev, timeout_s=1.0, spec=spec)
        t.join()
        assert c.level == "FAIL" and "no valid RDR1 frame" in c.message and "baud" in c.fix

        sim = RadarSimulator(FlightScript(), SimConfig(ng_per_min=0.0), spec)
        data, _ = sim.generate(200)
        t = threading.Timer(0.2, feed, args=(data,))
        t.start()
        c = doctor.check_source(dev, timeout_s=3.0, spec=spec)
        t.join()
        assert c.level == "OK" and re.search(r": \d+ frames", c.message), c
    finally:
        os.close(master)
        os.close(slave)


def test_ftdi_latency_timer(tmp_path, monkeypatch):
    from serial.tools import list_ports
    from serial.tools.list_ports_common import ListPortInfo

    port = ListPortInfo("/dev/ttyUSB0", skip_link_detection=True)
    port.description, port.hwid = "FT232R USB UART", "USB VID:PID=0403:6001"
    monkeypatch.setattr(list_ports, "comports", lambda: [port])
    lt = tmp_path / "ttyUSB0" / "latency_timer"
    lt.parent.mkdir()
    lt.write_text("16\n")
    (c,) = doctor.check_serial_ports(str(tmp_path))
    assert c.level == "WARN" and "latency timer 16 ms" in c.message
    assert c.fix.startswith(f"echo 1 | sudo tee {lt}")
    lt.write_text("1\n")
    (c,) = doctor.check_serial_ports(str(tmp_path))
    assert c.level == "OK" and "latency timer 1 ms" in c.message
    monkeypatch.setattr(list_ports, "comports", lambda: [])
    (c,) = doctor.check_serial_ports(str(tmp_path))
    assert c.level == "WARN" and "no serial ports" in c.message


def test_disk_thresholds(tmp_path, monkeypatch):
    import shutil
    from collections import namedtuple

    usage = namedtuple("usage", "total used free")
    for free, level in ((100 << 30, "OK"), (5 << 30, "WARN"), (100 << 20, "FAIL")):
        monkeypatch.setattr(shutil, "disk_usage", lambda p, f=free: usage(1, 1, f))
        c = doctor.check_disk(str(tmp_path / "not-made-yet"))
        assert c.level == level, c
        assert "GB free" in c.message


def test_permission_of_the_source_device(tmp_path):
    dev = tmp_path / "ttyFAKE"
    dev.write_bytes(b"")
    dev.chmod(0)
    c = doctor.check_permission(str(dev))
    if os.geteuid() == 0:  # root may open any device
        assert c.level == "OK" and "readable and writable" in c.message
    else:
        assert c.level == "FAIL" and "permission denied" in c.message and "dialout" in c.fix
    c = doctor.check_permission("sim://")
    assert c.level == "OK" and "needs no device permission" in c.message
