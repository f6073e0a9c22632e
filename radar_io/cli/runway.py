"""``radar-io runway``: aircraft attitude, height and lateral offset from nose-camera runway images.

Kept light at import time (the main CLI imports it for every command): OpenCV and
numpy are imported only when the sub-command runs.
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from radar_io.errors import VisionError

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp"}

EPILOG = """\
output: one JSON object per image (or video frame) per line on stdout with
image, found, bank_deg, pitch_deg, yaw_deg, height_m (above the runway),
lateral_m (right of the centre line), quality (0..1), and reason when no runway
was found.  Angles: bank right wing down +, pitch nose up +, yaw nose right of
the runway direction +.  Pixel coordinates: x right, y down, (0,0) = centre of
the top-left pixel.

points file (--points), pixel coordinates, two or more points per line:
  {"horizon": [[x,y],...], "left_edge": [[x,y],...], "right_edge": [[x,y],...]}
"""


def add_subparser(subparsers: Any) -> None:
    """Register the ``runway`` sub-command on the main CLI's sub-parser collection."""
    p = subparsers.add_parser(
        "runway",
        help="attitude, height and lateral offset from nose-camera runway images",
        description=__doc__.splitlines()[0].split(": ", 1)[1],
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("images", nargs="*", metavar="IMAGE", help="image file(s) to process")
    p.add_argument("--focal-px", type=float, required=True, metavar="F", help="focal length in pixels")
    p.add_argument(
        "--half-width-m", type=float, required=True, metavar="D",
        help="runway half-width d in metres (width / 2)"
    )
    p.add_argument(
        "--principal-point", metavar="CX,CY", help="principal point in pixels (default: image centre)"
    )
    p.add_argument(
        "--camera-offset",
        metavar="X,Y,Z",
        help="camera position relative to the aircraft reference point, body axes forward,right,down [m]",
    )
    p.add_argument("--points", metavar="FILE", help="manual mode: JSON file of picked points (see below)")
    p.add_argument(
        "--video",
        metavar="SOURCE",
        help="process a sequence: a video file, a directory of frames or a glob pattern (quote it)",
    )
    p.add_argument(
        "--threshold", type=int, metavar="LEVEL", help="fixed binary threshold 0..255 instead of Otsu"
    )
    p.set_defaults(func=run)


# --------------------------------------------------------------------------- argument checks
def _floats(text: str | None, n: int, what: str) -> tuple[float, ...] | None:
    if text is None:
        return None
    parts = text.replace(" ", "").split(",")
    try:
        vals = tuple(float(v) for v in parts)
    except ValueError:
        vals = ()
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise VisionError(f"{what} must be {n} comma-separated numbers, got {text!r}")
    return vals


def _check_args(args: argparse.Namespace) -> None:
    if not (math.isfinite(args.focal_px) and args.focal_px > 0):
        raise VisionError(f"--focal-px must be a positive number of pixels, got {args.focal_px}")
    if not (math.isfinite(args.half_width_m) and args.half_width_m > 0):
        raise VisionError(f"--half-width-m must be a positive number of metres, got {args.half_width_m}")
    if args.threshold is not None and not 0 <= args.threshold <= 255:
        raise VisionError(f"--threshold must be 0..255, got {args.threshold}")
    if args.video and args.points:
        raise VisionError("--video and --points cannot be combined")
    if args.video and args.images:
        raise VisionError("give either IMAGE files or --video, not both")
    if args.points and len(args.images) > 1:
        raise VisionError("--points applies to one image; give at most one IMAGE")
    if not args.video and not args.points and not args.images:
        raise VisionError("nothing to do: give IMAGE file(s), --video SOURCE or --points FILE")
    for path in args.images:
        if not Path(path).is_file():
            raise VisionError(f"image not found: {path}")


def _read_image(path: str) -> Any:
    import cv2

    img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise VisionError(f"cannot read image {path}: not an image file OpenCV can decode")
    return img


def _emit(record: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(record) + "\n")
    sys.stdout.flush()


# --------------------------------------------------------------------------- sequences
def _frames(source: str) -> tuple[Iterator[tuple[str, int, Any]], int | None]:
    """Yield ``(label, index, grey image or None if unreadable)`` for a video file, a directory of
    frames or a glob pattern; also returns the frame count when known."""
    import cv2

    src = Path(source)
    if src.is_dir():
        files = sorted(str(f) for f in src.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise VisionError(f"no image files in directory {source}")
    elif src.is_file():
        cap = cv2.VideoCapture(str(src))
        if not cap.isOpened():
            raise VisionError(f"cannot open video {source}")
        total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) or None

        def gen_video() -> Iterator[tuple[str, int, Any]]:
            i = 0
            try:
                while True:
                    ok, frame = cap.read()
                    if not ok:
                        break
                    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
                    yield f"{source}#{i}", i, gray
                    i += 1
            finally:
                cap.release()
            if i == 0:
                raise VisionError(f"cannot read any frame from video {source}")

        return gen_video(), total
    else:
        files = sorted(f for f in glob.glob(source) if Path(f).suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise VisionError(
                f"video source not found (no such file, directory or matching frames): {source}")

    def gen_files() -> Iterator[tuple[str, int, Any]]:
        for i, f in enumerate(files):
            yield f, i, cv2.imread(f, cv2.IMREAD_GRAYSCALE)  # None: unreadable frame

    return gen_files(), len(files)


# --------------------------------------------------------------------------- main
def run(args: argparse.Namespace) -> int:
    """Entry point of ``radar-io runway``; returns the exit code."""
    _check_args(args)
    pp_v = _floats(args.principal_point, 2, "--principal-point")
    off_v = _floats(args.camera_offset, 3, "--camera-offset")
    pp = None if pp_v is None else (pp_v[0], pp_v[1])
    offset = None if off_v is None else (off_v[0], off_v[1], off_v[2])

    from radar_io.vision.chain import ChainParams, RunwayResult, RunwayTracker, find_runway

    params = ChainParams(threshold=args.threshold)

    if args.points:
        from radar_io.vision.manual import load_points, pose_from_points

        points = load_points(args.points)
        if args.images:
            img = _read_image(args.images[0])
            h, w = img.shape[:2]
            pp = pp or ((w - 1) / 2.0, (h - 1) / 2.0)
        elif pp is None:
            raise VisionError("--points without an IMAGE needs --principal-point")
        res = pose_from_points(points, args.focal_px, args.half_width_m, pp, camera_offset_m=offset,
                               params=params)
        _emit({"image": args.images[0] if args.images else None, "points": args.points, **res.to_dict()})
        return 0

    if args.video:
        frames, total = _frames(args.video)
        tracker = RunwayTracker(args.focal_px, args.half_width_m, pp, camera_offset_m=offset,
                                params=params)
        from radar_io.cli.progress import Progress

        progress = Progress("runway", total=total or None, unit="frames", scale=1.0)
        n = found = 0
        for label, index, img in frames:
            if img is None:  # one bad frame in a sequence is reported, not fatal
                res = RunwayResult.not_found(f"cannot read image {label}")
            else:
                res = tracker.process(img)
            _emit({"image": label, "frame": index, **res.to_dict()})
            n += 1
            found += res.found
            progress.update(n, f"runway found in {found}")
        progress.close(f"{n} frames, runway found in {found}")
        return 0

    for path in args.images:
        res = find_runway(_read_image(path), args.focal_px, args.half_width_m, pp,
                          camera_offset_m=offset, params=params)
        _emit({"image": path, **res.to_dict()})
    return 0
