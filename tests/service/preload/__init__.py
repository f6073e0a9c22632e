"""LD_PRELOAD shims for a service in a child process, compiled by the test that uses them.

* ``mono_sleep.c``: monotonic sleeps straight to the kernel, preloaded before libfaketime
  (whose 0.9.10 breaks them with ``FAKETIME_DONT_FAKE_MONOTONIC=1``, its issue 426).
* ``slow_fsync.c``: fsync / fdatasync under a directory delayed, each call logged with the
  calling thread's kernel name.

:func:`name_threads` gives every Python thread of the child its name in the kernel too
(``radar-reader``, ``rdrlog-writer`` …; Python 3.11 does not), so the shim's log says
which thread called.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

HERE = Path(__file__).resolve().parent
LIBFAKETIME = Path("/usr/lib/x86_64-linux-gnu/faketime/libfaketime.so.1")


def compile_shim(name: str, out_dir: Path, cc: str) -> Path:
    """``out_dir/NAME.so`` built from ``NAME.c`` with the C compiler ``cc``."""
    out = out_dir / f"{name}.so"
    subprocess.run([cc, "-shared", "-fPIC", "-O2", "-Wall", "-o", str(out),
                    str(HERE / f"{name}.c"), "-ldl"], check=True, capture_output=True)
    return out


SITE = """\
import ctypes, threading
_prctl = ctypes.CDLL(None).prctl
_inner = threading.Thread._bootstrap_inner
def _named(self):
    try:
        _prctl(15, self.name.encode()[:15], 0, 0, 0)  # PR_SET_NAME
    except Exception:
        pass
    _inner(self)
threading.Thread._bootstrap_inner = _named
"""


def name_threads(site_dir: Path) -> str:
    """Write a ``sitecustomize.py`` naming each thread in the kernel; returns a PYTHONPATH
    with it first (then the caller's)."""
    (site_dir / "sitecustomize.py").write_text(SITE, encoding="utf-8")
    return os.pathsep.join([str(site_dir)] + [p for p in os.environ.get("PYTHONPATH", "")
                                              .split(os.pathsep) if p])
