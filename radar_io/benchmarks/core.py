"""``radar-io bench``: throughput of the decoding paths, with a memory-bandwidth reference.

All figures come from the same run on one core (numpy's element-wise work is
single-threaded); each is the best of ``repeat`` timings, as this 2-core virtual
machine's speed varies by tens of per cent from moment to moment. Streams are made by the simulator (a realistic approach at
1 kHz, with NG dropouts and sync events); the damaged stream has 1 % of its
bytes replaced (XOR with a random non-zero byte).
"""

from __future__ import annotations

import importlib.util
import os
import platform
import time
from typing import Any

import numpy as np

from radar_io.decoding.decoders import FrameDecoder, decode_bytes
from radar_io.framing.framers import Framer
from radar_io.simulation.radar import RadarSimulator, SimConfig
from radar_io.wirespec.frame import load_spec


def _best(fn: Any, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def corrupt_bytes(data: bytes, fraction: float, seed: int = 7) -> bytes:
    """``data`` with ``fraction`` of its bytes XORed with a random non-zero byte."""
    rng = np.random.default_rng(seed)
    b = np.frombuffer(data, dtype=np.uint8).copy()
    idx = rng.choice(b.size, int(b.size * fraction), replace=False)
    b[idx] ^= rng.integers(1, 256, idx.size, dtype=np.uint8)
    return b.tobytes()


def run_bench(frames: int = 2_000_000, repeat: int = 5, per_frame_frames: int = 100_000,
              include_plugins: bool = True, serve_seconds: float = 5.0) -> dict[str, Any]:
    """All figures; ``serve_seconds`` = 0 skips the live-service latency run."""
    spec = load_spec()
    sim = RadarSimulator(config=SimConfig(seed=11, tod_start_s=36000.0, loop=True), spec=spec)
    clean, _ = sim.generate(frames)
    damaged = corrupt_bytes(clean, 0.01)
    n_clean = frames

    t_clean = _best(lambda: decode_bytes(clean, spec=spec), repeat)
    check = decode_bytes(damaged, spec=spec)
    t_dam = _best(lambda: decode_bytes(damaged, spec=spec), repeat)

    pf = clean[: per_frame_frames * spec.length]

    def per_frame() -> None:
        framer, dec = Framer(spec), FrameDecoder(spec)
        decode = dec.decode
        for k in range(0, len(pf), 4096):  # serial-sized reads
            for fr in framer.feed(pf[k:k + 4096]):
                decode(fr)

    t_pf = _best(per_frame, repeat)

    src = np.frombuffer(clean, dtype=np.uint8)
    dst = np.empty_like(src)
    np.copyto(dst, src)  # fault the pages in first
    t_copy = _best(lambda: np.copyto(dst, src), repeat)
    memcpy_fps = len(clean) / t_copy / spec.length

    res: dict[str, Any] = {
        "machine": f"{platform.machine()} {os.cpu_count()} cpu, numpy {np.__version__}",
        "frames_clean": n_clean,
        "per_frame_fps": per_frame_frames / t_pf,
        "batch_clean_fps": n_clean / t_clean,
        "batch_damaged_1pct_fps": n_clean / t_dam,
        "batch_damaged_1pct_accepted": check.stats["frames"],
        "memcpy_bytes_per_s": len(clean) / t_copy,
        "memcpy_ref_fps": memcpy_fps,
        "batch_clean_vs_memcpy": (n_clean / t_clean) / memcpy_fps,
        "batch_damaged_vs_memcpy": (n_clean / t_dam) / memcpy_fps,
        "per_frame_vs_memcpy": (per_frame_frames / t_pf) / memcpy_fps,
    }
    if serve_seconds > 0:
        from radar_io.benchmarks.service_load import bench_service

        res.update(bench_service(serve_seconds))
    if include_plugins and importlib.util.find_spec("radar_io.vision") is not None:
        try:
            from radar_io.benchmarks.runway import bench_runway  # type: ignore[import-not-found]

            res.update(bench_runway())
        except ImportError:
            pass
    return res
