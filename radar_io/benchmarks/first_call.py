"""Where the first ``decode_bytes`` call of a fresh process spends its time (user and system CPU).

``python -m radar_io.benchmarks.first_call FILE [ALLOC]`` (run it in a fresh process) prints
the CPU seconds of: importing the decoder, loading the spec, building the framer and decoder
tables, allocating the output columns, framing, and decoding into them (system time = page
faults). ALLOC is a ``batch_decoder.column_array`` mode (default: the decoder's default).
"""

from __future__ import annotations

import resource
import sys
from itertools import pairwise
from pathlib import Path


def _cpu() -> tuple[float, float]:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime, r.ru_stime


def breakdown(path: str, block_frames: int = 1 << 16, alloc: str | None = None
              ) -> dict[str, tuple[float, float]]:
    """(user s, sys s) per stage of one chunked decode of the file, as ``decode_bytes`` does it."""
    data = Path(path).read_bytes()
    marks = [("start", _cpu())]
    from radar_io.decoding import batch_decoder
    from radar_io.decoding.batch_decoder import BatchDecoder
    from radar_io.framing.core import BatchFramer
    from radar_io.wirespec.frame import load_spec

    marks.append(("import", _cpu()))
    spec = load_spec()
    marks.append(("spec", _cpu()))
    framer, dec = BatchFramer(spec), BatchDecoder(spec)
    marks.append(("tables", _cpu()))
    if alloc:
        batch_decoder.COLUMN_ALLOC = alloc
    out = dec.allocate(len(data) // spec.length)
    marks.append(("allocate", _cpu()))
    mv = memoryview(data)
    s, framing, decoding = 0, [0.0, 0.0], [0.0, 0.0]
    step = block_frames * spec.length
    for off in range(0, len(data), step):
        a = _cpu()
        blocks = framer.feed_blocks(mv[off:off + step])
        b = _cpu()
        s = dec.decode_into(blocks, out, s)
        c = _cpu()
        for acc, x, y in ((framing, a, b), (decoding, b, c)):
            acc[0] += y[0] - x[0]
            acc[1] += y[1] - x[1]
    res = {name: (m[0] - p[0], m[1] - p[1]) for (_, p), (name, m) in pairwise(marks)}
    res["framing"] = (framing[0], framing[1])
    res["decoding"] = (decoding[0], decoding[1])
    return res


if __name__ == "__main__":
    alloc = sys.argv[2] if len(sys.argv) > 2 else None
    total = [0.0, 0.0]
    for stage, (user, system) in breakdown(sys.argv[1], alloc=alloc).items():
        if stage in ("allocate", "framing", "decoding"):
            total[0] += user
            total[1] += system
        print(f"{stage:9s} user {user:.3f} s  sys {system:.3f} s")
    print(f"{'alloc+frame+decode':9s} user {total[0]:.3f} s  sys {total[1]:.3f} s  "
          f"({alloc or 'default'})")
