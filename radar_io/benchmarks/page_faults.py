"""System time of writing fresh output columns: numpy (huge-page advice) vs a plain anonymous mmap.

``python -m radar_io.benchmarks.page_faults numpy|mmap|populate|huge`` writes 15
float64 columns of 2 M rows (229 MiB) and prints user / system time and page faults.
"""

from __future__ import annotations

import mmap
import resource
import sys

import numpy as np


def _usage() -> tuple[float, float, int]:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime, r.ru_stime, r.ru_minflt


def write_columns(mode: str, rows: int = 2_000_000, columns: int = 15) -> dict[str, float]:
    """Allocate ``columns`` float64 columns by ``mode`` and write them once; user/sys s, faults."""
    a = _usage()
    keep = []
    for _ in range(columns):
        if mode == "numpy":
            x = np.empty(rows)
        else:
            flags = mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS
            if mode == "populate":
                flags |= mmap.MAP_POPULATE
            m = mmap.mmap(-1, rows * 8, flags=flags)
            if mode == "huge":
                m.madvise(mmap.MADV_HUGEPAGE)
            x = np.frombuffer(m, dtype=np.float64)
        x.fill(1.0)
        keep.append(x)
    b = _usage()
    return {"user_s": b[0] - a[0], "sys_s": b[1] - a[1], "faults": b[2] - a[2],
            "mib": columns * rows * 8 / 2**20}


if __name__ == "__main__":
    r = write_columns(sys.argv[1] if len(sys.argv) > 1 else "mmap")
    print(f"{sys.argv[1:2]} user {r['user_s']:.3f} s, sys {r['sys_s']:.3f} s, "
          f"{r['faults']} faults, {r['mib']:.0f} MiB")
