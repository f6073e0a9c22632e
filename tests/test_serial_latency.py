"""Low-latency serial: the source asks the driver for ASYNC_LOW_LATENCY and carries on when
the port cannot (a pty); the udev rule sets the FTDI latency timer to 1 ms (issue 10 item 8)."""

from __future__ import annotations

import logging
import re
from pathlib import Path

from radar_io.benchmarks.service_load import Pty
from radar_io.sources.serialport import SerialSource

RULES = Path(__file__).resolve().parent.parent / "deploy" / "99-radar.rules"


def test_pty_refuses_low_latency_with_one_log_line_and_still_reads(caplog):
    pty = Pty()
    src = SerialSource(pty.path + "?baudrate=115200")
    caplog.set_level(logging.INFO, "radar_io.sources")
    try:
        src.open()
        pty.write(b"\xeb\x90hello")
        got = b""
        for _ in range(50):
            got += src.read(0.1)
            if len(got) >= 7:
                break
        assert got == b"\xeb\x90hello"
    finally:
        src.close()
        pty.close()
    lines = [r.getMessage() for r in caplog.records if "low-latency" in r.getMessage()]
    assert len(lines) == 1, lines
    # pyserial tried the TIOCSSERIAL ioctl (a pty has no serial_struct) and said why it failed
    assert pty.path in lines[0] and "ASYNC_LOW_LATENCY" in lines[0]


def test_loop_url_has_no_low_latency_mode_and_works(caplog):
    caplog.set_level(logging.INFO, "radar_io.sources")
    src = SerialSource("loop://")
    src.open()
    try:
        src.write(b"abc")
        assert src.read(0.5) == b"abc"
    finally:
        src.close()
    assert any("not available" in r.getMessage() for r in caplog.records)


def parse_rules(text: str) -> list[list[tuple[str, str, str]]]:
    """udev rules as lists of (key, operator, value); comments and blank lines skipped."""
    rules = []
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        pairs = re.findall(r'([A-Za-z_]+(?:\{[^}]*\})?)\s*(==|!=|\+=|-=|:=|=)\s*"([^"]*)"', line)
        rest = re.sub(r'([A-Za-z_]+(?:\{[^}]*\})?)\s*(==|!=|\+=|-=|:=|=)\s*"([^"]*)"', "", line)
        assert rest.replace(",", "").strip() == "", f"unparsed text in rule: {rest!r}"
        rules.append(pairs)
    return rules


def test_udev_rule_sets_ftdi_latency_timer_to_1ms():
    rules = parse_rules(RULES.read_text())
    hits = [r for r in rules if ("ATTR{latency_timer}", "=", "1") in r]
    assert len(hits) == 1
    keys = {(k, op): v for k, op, v in hits[0]}
    # latency_timer lives on the usb-serial device (the tty's parent), driven by ftdi_sio
    assert keys[("SUBSYSTEM", "==")] == "usb-serial"
    assert keys[("DRIVER", "==")] == "ftdi_sio"
    assert keys[("ATTRS{idVendor}", "==")] == "0403"
    assert keys[("ATTRS{idProduct}", "==")] == "6001"
    link = [r for r in rules if ("SYMLINK", "+=", "radar") in r]
    assert len(link) == 1
