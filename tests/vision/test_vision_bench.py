"""The runway-chain benchmark."""

from __future__ import annotations

import cv2

from radar_io.benchmarks.runway import bench_runway


def test_bench_runway_reports_frame_rates_and_restores_threads():
    threads = cv2.getNumThreads()
    out = bench_runway(seconds=0.6)
    assert set(out) == {"runway_chain_fps_640x480", "runway_tracker_fps_640x480"}
    # a sanity floor well under the 30 frames/s target, so a loaded test machine does not fail it
    assert all(isinstance(v, float) and v > 5.0 for v in out.values()), out
    assert cv2.getNumThreads() == threads
