"""Runway-vision video jobs: one worker thread, a short queue, cancellable, streamed.

``POST /api/runway`` with a video spools the body to a temporary file and submits a
:class:`RunwayJob`; a worker thread starts a child process that decodes the video one
frame at a time (never more than one frame in memory), runs
:class:`~radar_io.vision.chain.RunwayTracker` on it and streams one JSON line per frame
back; only the per-frame pose dicts are kept. The event loop never runs OpenCV: it only reads
job states. One job runs at a time (``workers``), ``max_queued`` more may wait; beyond
that :meth:`RunwayJobs.submit` raises :class:`QueueFull` (HTTP 429).

The child runs at nice 10 with OpenCV on one thread and its own interpreter (no GIL
shared with the service), so the radar reader and the event loop keep answering. Its
stderr goes to a file in the spool directory (never a pipe that could fill and stall it),
and a job running longer than its wall-clock limit (config ``runway_job_timeout_s``,
monotonic clock) has its child terminated and fails saying so; the worker is then free.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import threading
import time
import uuid
import weakref
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from radar_io.errors import ConflictError, NotFoundError, RadarIOError

log = logging.getLogger("radar_io.runway")

MAX_FRAMES = 20000  #: frames processed from one uploaded video
STATES = ("queued", "running", "done", "failed", "cancelled")


class QueueFull(ConflictError):
    """Every worker is busy and the queue is full (HTTP 429)."""


@dataclass
class RunwayJob:
    """One video: camera parameters, progress and, once done, the per-frame results."""

    id: str
    video: Path
    focal_px: float
    half_width_m: float
    principal_point: tuple[float, float] | None
    state: str = "queued"
    frames_done: int = 0
    frames_total: int | None = None
    result: dict[str, Any] | None = None
    error: str | None = None
    created_unix_s: float = field(default_factory=time.time)  # a label (wall clock)
    finished_unix_s: float | None = None
    cancel: threading.Event = field(default_factory=threading.Event, repr=False)

    def as_dict(self) -> dict[str, Any]:
        return {"job": self.id, "state": self.state, "frames_done": self.frames_done,
                "frames_total": self.frames_total, "result": self.result, "error": self.error,
                "created_unix_s": self.created_unix_s, "finished_unix_s": self.finished_unix_s}


#: wall-clock limit of one job (s), measured with the monotonic clock from its start
DEFAULT_TIMEOUT_S = 1800.0
#: bytes of the child's stderr shown in a failed job's error (the last line of this tail)
STDERR_TAIL_BYTES = 4096


def worker_command(job: RunwayJob, max_frames: int) -> list[str]:
    """The child's command line: ``python -m radar_io.service.runway_jobs VIDEO …``."""
    import sys

    pp = job.principal_point or ("", "")
    return [sys.executable, "-m", "radar_io.service.runway_jobs", str(job.video),
            repr(job.focal_px), repr(job.half_width_m), str(pp[0]), str(pp[1]), str(max_frames)]


def process_video(job: RunwayJob, max_frames: int = MAX_FRAMES,
                  timeout_s: float = DEFAULT_TIMEOUT_S,
                  command: Callable[[RunwayJob, int], list[str]] = worker_command) -> None:
    """Run the tracker over ``job.video`` in a child process, updating ``job`` as frames come.

    The child (``command(job, max_frames)``, by default :func:`worker_command`; nice 10)
    decodes one frame at a time and writes one JSON line per frame on stdout; a process of
    its own keeps OpenCV and the chain's Python code off the service's GIL. Its stderr goes
    to a file beside the upload (``VIDEO.stderr``, removed afterwards), so a chatty decoder
    can never fill a pipe and stall the child; the last line of its tail explains a failed
    child. Cancelling kills the child; so does running longer than ``timeout_s``
    (monotonic), which fails the job saying so.
    """
    import json
    import subprocess

    pkg_root = str(Path(__file__).resolve().parents[2])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [pkg_root] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])}
    cmd = command(job, max_frames)
    err_path = job.video.with_name(job.video.name + ".stderr")
    timed_out = threading.Event()
    with open(err_path, "wb") as err_file:
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=err_file, env=env,
                                preexec_fn=_nice_child if os.name == "posix" else None)
    try:
        watcher = threading.Thread(target=_watch, args=(job, proc, timeout_s, timed_out),
                                   name=f"runway-watch-{job.id}", daemon=True)
        watcher.start()
        frames: list[dict[str, Any]] = []
        error: str | None = None
        assert proc.stdout is not None
        with proc.stdout:
            for line in proc.stdout:
                doc = json.loads(line)
                if "frame" in doc:
                    frames.append(doc)
                    job.frames_done = len(frames)
                elif "frames_total" in doc:
                    job.frames_total = doc["frames_total"]
                elif "error" in doc:
                    error = doc["error"]
        proc.wait()
        watcher.join()
        err = _tail(err_path)
    finally:
        if proc.poll() is None:  # an exception above: never leave the child running
            proc.kill()
            proc.wait()
        try:
            os.unlink(err_path)
        except OSError:
            pass
    if job.cancel.is_set():
        return
    if timed_out.is_set():
        raise RadarIOError(f"runway job stopped: longer than its time limit of {timeout_s:g} s "
                           f"(runway_job_timeout_s) after {len(frames)} frames")
    if error is not None:
        raise RadarIOError(error)
    if proc.returncode != 0:
        last = err.strip().splitlines()[-1] if err.strip() else f"exit status {proc.returncode}"
        raise RadarIOError(f"runway worker failed: {last}")
    if not frames:
        raise RadarIOError("the video holds no frames")
    job.frames_total = len(frames)
    job.result = {"frames": frames, "found": sum(1 for f in frames if f["found"])}


def _watch(job: RunwayJob, proc: Any, timeout_s: float, timed_out: threading.Event) -> None:
    """Kill the child when the job is cancelled or has run ``timeout_s`` (monotonic)."""
    deadline = time.monotonic() + timeout_s
    while proc.poll() is None:
        left = deadline - time.monotonic()
        if left <= 0:
            timed_out.set()
            log.warning("runway job %s: time limit of %g s reached, stopping its worker",
                        job.id, timeout_s)
            _end(proc)
            return
        if job.cancel.wait(min(0.2, left)):
            proc.kill()
            return


def _end(proc: Any, grace_s: float = 2.0) -> None:
    """SIGTERM, then SIGKILL after ``grace_s``."""
    import subprocess

    proc.terminate()
    try:
        proc.wait(grace_s)
    except subprocess.TimeoutExpired:
        proc.kill()


def _tail(path: Path, size: int = STDERR_TAIL_BYTES) -> str:
    """The last ``size`` bytes of a file as text ('' when it cannot be read)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - size))
            return f.read().decode(errors="replace")
    except OSError:
        return ""


def _nice_child() -> None:
    os.nice(10)


def _worker_main(argv: list[str]) -> int:
    """The child: one JSON line per frame on stdout (``frames_total`` first, ``error`` on failure)."""
    import json
    import sys

    import cv2

    from radar_io.vision.chain import RunwayTracker

    video, focal, half_width, cx, cy, max_frames = argv
    cv2.setNumThreads(1)
    out = sys.stdout
    pp = (float(cx), float(cy)) if cx and cy else None
    cap = cv2.VideoCapture(video)
    try:
        if not cap.isOpened():
            out.write(json.dumps({"error": "cannot decode the video"}) + "\n")
            return 0
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        limit = int(max_frames)
        out.write(json.dumps({"frames_total": min(n, limit) if n > 0 else None}) + "\n")
        out.flush()
        tracker = RunwayTracker(float(focal), float(half_width), pp)
        k = 0
        while k < limit:
            ok, img = cap.read()  # one frame in memory at a time
            if not ok:
                break
            gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
            out.write(json.dumps({"frame": k, **tracker.process(gray).to_dict()}) + "\n")
            out.flush()
            k += 1
    except RadarIOError as exc:
        out.write(json.dumps({"error": str(exc)}) + "\n")
    finally:
        cap.release()
    return 0


class RunwayJobs:
    """The job table and its worker thread(s); all methods are safe from any thread."""

    def __init__(self, workers: int = 1, max_queued: int = 2, keep_finished: int = 16,
                 max_frames: int = MAX_FRAMES, spool_dir: Path | None = None,
                 timeout_s: float = DEFAULT_TIMEOUT_S,
                 command: Callable[[RunwayJob, int], list[str]] = worker_command) -> None:
        """``timeout_s``: wall-clock limit of one job (monotonic); ``command``: the child's
        command line for a job (the vision worker of this module unless given)."""
        self.max_queued = max_queued
        self.keep_finished = keep_finished
        self.max_frames = max_frames
        self.timeout_s = timeout_s
        self.command = command
        self.spool_dir = Path(tempfile.mkdtemp(prefix="radar-runway-", dir=spool_dir))
        self._cleanup = weakref.finalize(self, shutil.rmtree, str(self.spool_dir), True)
        self._jobs: OrderedDict[str, RunwayJob] = OrderedDict()
        self._queue: deque[RunwayJob] = deque()
        self._cond = threading.Condition()
        self._running = 0
        self._closed = False
        self._threads = [threading.Thread(target=self._work, name=f"runway-job-{k}", daemon=True)
                         for k in range(workers)]
        for t in self._threads:
            t.start()

    # -- API ---------------------------------------------------------------------------------
    def new_spool_path(self) -> Path:
        """A fresh path in the spool directory for an upload."""
        return self.spool_dir / f"{uuid.uuid4().hex}.upload"

    def submit(self, video: Path, focal_px: float, half_width_m: float,
               principal_point: tuple[float, float] | None) -> RunwayJob:
        """Queue a video (the job owns the file from now on). QueueFull when full."""
        with self._cond:
            if self._closed:
                raise ConflictError("the service is shutting down")
            if len(self._queue) >= self.max_queued:
                raise QueueFull(f"runway job queue full ({self._running} running, "
                                f"{len(self._queue)} queued): try again later")
            job = RunwayJob(uuid.uuid4().hex[:12], video, focal_px, half_width_m, principal_point)
            self._jobs[job.id] = job
            self._queue.append(job)
            self._trim()
            self._cond.notify()
            return job

    def get(self, job_id: str) -> RunwayJob:
        with self._cond:
            job = self._jobs.get(job_id)
        if job is None:
            raise NotFoundError(f"no runway job {job_id!r}")
        return job

    def cancel(self, job_id: str) -> RunwayJob:
        """Cancel a queued job at once, a running one at its next frame."""
        with self._cond:
            job = self._jobs.get(job_id)
            if job is None:
                raise NotFoundError(f"no runway job {job_id!r}")
            job.cancel.set()
            if job.state == "queued":
                self._queue.remove(job)
                self._finish(job, "cancelled")
            return job

    def stats(self) -> dict[str, Any]:
        with self._cond:
            return {"running": self._running, "queued": len(self._queue),
                    "max_queued": self.max_queued}

    def close(self, timeout_s: float = 5.0) -> None:
        """Cancel everything, stop the workers, remove the spool directory."""
        with self._cond:
            self._closed = True
            for job in list(self._jobs.values()):
                job.cancel.set()
            while self._queue:
                self._finish(self._queue.popleft(), "cancelled")
            self._cond.notify_all()
        for t in self._threads:
            t.join(timeout_s)
        self._cleanup()

    # -- worker ------------------------------------------------------------------------------
    def _work(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                job = self._queue.popleft()
                job.state = "running"
                self._running += 1
            state, error = "done", None
            try:
                process_video(job, self.max_frames, self.timeout_s, self.command)
                if job.cancel.is_set():
                    state = "cancelled"
            except RadarIOError as exc:
                state, error = "failed", str(exc)
            except Exception as exc:  # a vision bug fails the job, not the worker
                log.exception("runway job %s failed", job.id)
                state, error = "failed", f"{type(exc).__name__}: {exc}"
            with self._cond:
                self._running -= 1
                self._finish(job, state, error)

    def _finish(self, job: RunwayJob, state: str, error: str | None = None) -> None:
        """Final state; the uploaded file is removed (lock held)."""
        job.state, job.error = state, error
        job.finished_unix_s = time.time()  # a label (wall clock)
        try:
            os.unlink(job.video)
        except OSError:
            pass
        self._trim()

    def _trim(self) -> None:
        finished = [j for j in self._jobs.values() if j.state in ("done", "failed", "cancelled")]
        for j in finished[: max(0, len(finished) - self.keep_finished)]:
            del self._jobs[j.id]


if __name__ == "__main__":
    import sys

    sys.exit(_worker_main(sys.argv[1:]))
