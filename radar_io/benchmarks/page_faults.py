"""System time of writing fresh output columns: numpy (huge-page advice) vs a plain anonymous mmap.

``python -m radar_io.benchmarks.page_faults numpy|mmap|populate|huge`` writes 15
float64 columns of 2 M rows (229 MiB) and prints user / system time and page faults.
"""
from __future__ import annotations

import mmap
import resource
import sys

import numpy as np

mode=sys.argv[1]
n=2_000_000; ncol=15
def u():
    r=resource.getrusage(resource.RUSAGE_SELF); return r.ru_utime, r.ru_stime, r.ru_minflt
a=u()
arrs=[]
for c in range(ncol):
    nb=n*8
    if mode=="numpy":
        x=np.empty(n)
    else:
        fl=mmap.MAP_PRIVATE|mmap.MAP_ANONYMOUS|(mmap.MAP_POPULATE if mode=="populate" else 0)
        m=mmap.mmap(-1, nb, flags=fl)
        if mode=="huge": m.madvise(mmap.MADV_HUGEPAGE)
        x=np.frombuffer(m, dtype=np.float64)
    x.fill(1.0)
    arrs.append(x)
b=u()
print(mode, f"user {b[0]-a[0]:.3f} sys {b[1]-a[1]:.3f} flt {b[2]-a[2]}  ({ncol*n*8/2**20:.0f} MiB)")
