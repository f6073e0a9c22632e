"""The runway-chain benchmark."""

from __future__ import annotations

import cv2
import pytest

from radar_io.benchmarks.runway import bench_runway


@pytest.mark.slow
def test_bench_runway_reports_frame_rates_and_restores_threads():
    """The benchmark runs both stages and gives OpenCV its thread count back. Its figures are
    measurements, not pass/fail criteria (no timing asserts in tests): they go in the docs."""
    threads = cv2.getNumThreads()
    out = bench_runway(seconds=0.3)
    assert set(out) == {"runway_chain_fps_640x480", "runway_tracker_fps_640x480"}
    assert cv2.getNumThreads() == threads
