"""Tracking: extended Kalman filter and Rauch–Tung–Striebel smoother over radar measurements.

``from radar_io.tracking.tracker import track_batch, iter_track, TrackParams``; the live
forward filter of the service's pipelines is :mod:`radar_io.tracking.live`. The
compiled loops live in :mod:`radar_io.tracking.kernels` (numba, imported on first use).
Models and equations: docs/tracking.md.
"""
