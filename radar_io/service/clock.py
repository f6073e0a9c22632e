"""Is the system clock synchronised (NTP / PTP)? Asked of whichever tool this system has —
``timedatectl``, systemd-timesyncd's state file, ``chronyc`` — off the event loop and the
reader thread, and cached.
"""

from __future__ import annotations

import shutil
import subprocess
import threading
import time
from pathlib import Path


def _run(cmd: list[str]) -> str | None:
    """stdout of ``cmd`` (None when absent, failing or slower than 3 s)."""
    if shutil.which(cmd[0]) is None:
        return None
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=3.0, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return r.stdout if r.returncode == 0 else None


def clock_sync_state() -> tuple[bool | None, str]:
    """(synchronised, how it was told); None when no tool can tell. Blocks up to ~6 s."""
    out = _run(["timedatectl", "show"])
    if out is not None:
        kv = dict(line.split("=", 1) for line in out.splitlines() if "=" in line)
        sync = kv.get("NTPSynchronized")
        if sync in ("yes", "no"):
            return sync == "yes", f"timedatectl: NTPSynchronized={sync}, NTP={kv.get('NTP', '?')}"
    if Path("/run/systemd/timesync/synchronized").exists():
        return True, "/run/systemd/timesync/synchronized"
    out = _run(["chronyc", "tracking"])
    if out is not None:
        kv = {k.strip(): v.strip() for k, _, v in (ln.partition(":") for ln in out.splitlines())}
        status = kv.get("Leap status", "?")
        return status == "Normal", f"chronyc: leap status {status}, {kv.get('System time', '')}"
    return None, "no timedatectl, systemd-timesyncd state or chronyc on this machine"


class ClockSync:
    """The last answer of :func:`clock_sync_state`, refreshed on a thread of its own when
    older than ``max_age_s`` (monotonic); :meth:`get` never waits."""

    def __init__(self, max_age_s: float = 60.0) -> None:
        self.max_age_s = max_age_s
        self.synchronized: bool | None = None
        self.how = "not asked yet"
        self._asked_mono: float | None = None
        self._busy = threading.Lock()

    def get(self) -> bool | None:
        """Synchronised (True / False), or None when unknown (or not asked yet)."""
        now = time.monotonic()
        if (self._asked_mono is None or now - self._asked_mono > self.max_age_s) \
                and self._busy.acquire(blocking=False):
            self._asked_mono = now
            threading.Thread(target=self._refresh, name="clock-sync", daemon=True).start()
        return self.synchronized

    def _refresh(self) -> None:
        try:
            self.synchronized, self.how = clock_sync_state()
        finally:
            self._busy.release()
