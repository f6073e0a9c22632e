"""System time of writing fresh output columns, by the way the memory is obtained.

``python -m radar_io.benchmarks.page_faults MODE [REPEAT]`` writes 15 float64 columns of
2 M rows (229 MiB) and prints user / system time and minor page faults. MODE:

* ``numpy`` — ``np.empty`` (numpy advises transparent huge pages on large arrays);
* ``mmap`` — a plain anonymous mapping per column (4 KiB pages, one fault each);
* ``populate`` — the same with ``MAP_POPULATE`` (the kernel faults it in at ``mmap``);
* ``populate_write`` — plain mapping, then ``madvise(MADV_POPULATE_WRITE)`` (Linux ≥ 5.14);
* ``huge`` — plain mapping with ``madvise(MADV_HUGEPAGE)``;
* ``huge_populate`` — ``MADV_HUGEPAGE`` then ``MADV_POPULATE_WRITE``.
"""

from __future__ import annotations

import mmap
import resource
import sys

import numpy as np

#: ``MADV_POPULATE_WRITE`` (linux/mman.h); ``mmap`` exports it from Python 3.12 on only
MADV_POPULATE_WRITE = getattr(mmap, "MADV_POPULATE_WRITE", 23)
MODES = ("numpy", "mmap", "populate", "populate_write", "huge", "huge_populate")


def _usage() -> tuple[float, float, int]:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime, r.ru_stime, r.ru_minflt


def _column(mode: str, rows: int) -> np.ndarray:
    if mode == "numpy":
        return np.empty(rows)
    flags = mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS
    if mode == "populate":
        flags |= mmap.MAP_POPULATE
    m = mmap.mmap(-1, rows * 8, flags=flags)
    if mode in ("huge", "huge_populate"):
        m.madvise(mmap.MADV_HUGEPAGE)
    if mode in ("populate_write", "huge_populate"):
        m.madvise(MADV_POPULATE_WRITE)
    return np.frombuffer(m, dtype=np.float64)


def write_columns(mode: str, rows: int = 2_000_000, columns: int = 15) -> dict[str, float]:
    """Allocate ``columns`` float64 columns by ``mode`` and write them once; user/sys s, faults."""
    if mode not in MODES:
        raise ValueError(f"mode {mode!r}: one of {', '.join(MODES)}")
    a = _usage()
    keep = []
    for _ in range(columns):
        x = _column(mode, rows)
        x.fill(1.0)
        keep.append(x)
    b = _usage()
    return {"user_s": b[0] - a[0], "sys_s": b[1] - a[1], "faults": b[2] - a[2],
            "mib": columns * rows * 8 / 2**20}


if __name__ == "__main__":
    mode = sys.argv[1] if len(sys.argv) > 1 else "mmap"
    r = write_columns(mode)
    print(f"{mode:14s} user {r['user_s']:.3f} s, sys {r['sys_s']:.3f} s, "
          f"{r['faults']} faults, {r['mib']:.0f} MiB")
