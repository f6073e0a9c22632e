"""Benchmark of the runway image chain (wired into ``radar-io bench`` by the main CLI)."""

from __future__ import annotations

import time

__all__ = ["bench_runway"]


def bench_runway(seconds: float = 3.0) -> dict[str, float]:
    """Frames per second of the full image chain on synthetic 640×480 frames, one core.

    Frames are rendered beforehand (not timed) from eight poses across the
    envelope with clutter, blur and noise.  Returns
    ``{"runway_chain_fps_640x480": …, "runway_tracker_fps_640x480": …}``: single
    frames searched in full, and a sequence processed with the region of interest
    around the previous vanishing point.  Each figure is measured for about
    ``seconds / 2``.  OpenCV's thread count is set to 1 and restored afterwards.
    """
    import cv2

    from radar_io.vision.chain import RunwayTracker, find_runway
    from radar_io.vision.synth import RunwayPose, RunwayScene, focal_for_fov, render_runway

    width, height = 640, 480
    f = focal_for_fov(width, 60.0)
    poses = [
        RunwayPose(0.0, -3.0, 0.0, 50.0, 0.0),
        RunwayPose(12.0, -8.0, 6.0, 300.0, 25.0),
        RunwayPose(-18.0, 3.0, -8.0, 8.0, -30.0),
        RunwayPose(5.0, -10.0, 3.0, 480.0, -40.0),
        RunwayPose(-7.0, 1.0, -2.0, 20.0, 10.0),
        RunwayPose(15.0, -5.0, 9.0, 120.0, -15.0),
        RunwayPose(-10.0, -1.0, 5.0, 5.0, 3.0),
        RunwayPose(2.0, 4.0, -6.0, 200.0, 35.0),
    ]
    frames = [render_runway(p, width, height, f, RunwayScene(seed=i)) for i, p in enumerate(poses)]
    sequence = [
        render_runway(RunwayPose(2.0 + 0.2 * i, -3.0, 1.0, 60.0 - i, 2.0), width, height, f,
                      RunwayScene(seed=i))
        for i in range(8)
    ]
    budget = max(float(seconds), 0.2) / 2.0
    old_threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        find_runway(frames[0], f, 22.5)  # warm-up

        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < budget:
            find_runway(frames[n % len(frames)], f, 22.5)
            n += 1
        chain_fps = n / (time.perf_counter() - t0)

        tracker = RunwayTracker(f, 22.5)
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < budget:
            tracker.process(sequence[n % len(sequence)])
            n += 1
        tracker_fps = n / (time.perf_counter() - t0)
    finally:
        cv2.setNumThreads(old_threads)
    return {
        "runway_chain_fps_640x480": round(chain_fps, 1),
        "runway_tracker_fps_640x480": round(tracker_fps, 1),
    }
