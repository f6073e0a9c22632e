"""Shared test fixtures. Tests read only files inside the repository (``tests/data/``,
``firmware_specs/``); nothing beside the clone.

Outside programs (chromium, mosquitto, tshark, ...): :func:`require_program` skips a test
with the reason locally; with ``CI=true`` in the environment any skipped test fails the
session (see :func:`pytest_sessionfinish`), so CI cannot go green on tests that never ran.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DATA = Path(__file__).resolve().parent / "data"
sys.path.insert(0, str(Path(__file__).resolve().parent))


def in_ci() -> bool:
    """True when the environment says this is a CI run (``CI=true``)."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def timing_bound(strict: float, loose: float, max_load_per_core: float = 1.0) -> float:
    """The bound an issue names for a timing figure (``strict``) when the machine is quiet —
    the 1-min load average at most ``max_load_per_core`` per core — else ``loose``: on a
    machine shared with other work a latency is mostly that work's, so the test then only
    guards against a gross regression. The figure itself is printed either way, and the
    benchmarks (``radar-io bench``) measure it on a quiet machine."""
    quiet = os.getloadavg()[0] / (os.cpu_count() or 1) <= max_load_per_core
    return strict if quiet else loose


def require_program(name: str, *alternatives: str) -> str:
    """Full path of the first of ``name, *alternatives`` found on PATH; skip the test with
    the reason when none is (in CI the skip then fails the session)."""
    for n in (name, *alternatives):
        p = shutil.which(n)
        if p:
            return p
    names = " / ".join((name, *alternatives))
    pytest.skip(f"outside program {names} is not installed (Debian package; .ci/run installs it)")
    raise AssertionError("unreachable")  # pytest.skip raises


_skipped: list[str] = []



#: in-process tests of tests/service/ (no server, browser or child process): in the fast subset
SERVICE_UNIT_MODULES = frozenset({"test_fanout_unit.py", "test_history.py", "test_limits_unit.py",
                                  "test_pipeline.py"})
#: other modules that start a service, a broker, a browser, tshark, a JVM or the CLI per case
SLOW_MODULES = frozenset({"test_spark.py", "test_mqtt.py", "test_asterix.py", "test_report.py",
                          "test_ch10_export.py", "test_track_cli.py", "test_end_to_end.py"})


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Every test that runs real servers, browsers or outside programs is ``slow``: the
    development subset ``pytest -m "not slow"`` leaves them out (CI runs everything)."""
    slow = pytest.mark.slow
    for item in items:
        path = Path(str(item.fspath))
        in_service = path.parent.name == "service" and path.name not in SERVICE_UNIT_MODULES
        if in_service or path.name in SLOW_MODULES:
            item.add_marker(slow)


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if report.skipped and not hasattr(report, "wasxfail"):   # an expected failure is no skip
        _skipped.append(report.nodeid)


def pytest_collectreport(report: pytest.CollectReport) -> None:
    if report.skipped:
        _skipped.append(report.nodeid or "collection")


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """With ``CI=true``, a session that skipped anything fails (exit 1)."""
    if not in_ci():
        return
    tr = session.config.pluginmanager.get_plugin("terminalreporter")

    def say(msg: str, **markup: bool) -> None:
        if tr is not None:
            tr.write_line(msg, **markup)
        else:
            print(msg, file=sys.stderr)

    bad = list(_skipped)
    if bad and session.exitstatus == 0:
        say(f"CI=true: {len(bad)} test(s) skipped, which CI does not allow: "
            + ", ".join(bad[:10]) + (" ..." if len(bad) > 10 else ""), red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


@pytest.fixture(scope="session")
def spec():
    from radar_io.wirespec.frame import load_spec

    return load_spec()


@pytest.fixture(scope="session")
def vectors() -> dict:
    """Outside RDR1 test vectors (copied into tests/data/, see tests/data/README.md)."""
    return json.loads((DATA / "rdr1_vectors.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="session")
def golden() -> dict:
    """Inputs and main's decoder output before the decoding rework (tests/data/README.md)."""
    import numpy as np

    with np.load(DATA / "rdr1_golden.npz") as z:
        return {k: z[k] for k in z.files}


def assert_golden(batch, golden: dict, key: str) -> None:
    """``batch`` has the golden ``key``'s columns (order, dtypes, values, NaN where NaN) and
    counters exactly."""
    import numpy as np

    assert list(batch.columns) == json.loads(str(golden[f"{key}/columns"]))
    assert batch.stats == json.loads(str(golden[f"{key}/stats"]))
    for col in batch.columns:
        want = golden[f"{key}/{col}"]
        assert batch[col].dtype == want.dtype, col
        assert np.array_equal(batch[col], want, equal_nan=want.dtype.kind == "f"), col


def fly_on_virtual_bus(channel: str, stop: threading.Event, duration_s: float = 60.0) -> None:
    """The simulated aircraft's recorder traffic on python-can's virtual bus ``channel``, in
    real time, until ``stop`` is set or ``duration_s`` has passed (run it on a thread)."""
    import can

    from radar_io.simulation.aircraft import AircraftSimulator
    from radar_io.simulation.radar import FlightScript, SimConfig

    bus = can.Bus(interface="virtual", channel=channel)
    sim = AircraftSimulator(FlightScript(), SimConfig(sync_every_s=2.0), duration_s=duration_s)
    t0, t = time.monotonic(), 0.0
    while not stop.is_set() and t < duration_s - 1.0:
        now = time.monotonic() - t0
        if now > t:
            sim.send(bus, t, now)
            t = now
        time.sleep(0.05)
    bus.shutdown()


def run_cli(*args: str, input: bytes | None = None, timeout: float = 300,
            env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run ``radar-io`` as a separate process, the way an operator would."""
    return subprocess.run([sys.executable, "-m", "radar_io.cli", *args], input=input,
                          capture_output=True, timeout=timeout, cwd=ROOT,
                          env={**os.environ, **(env or {})})
