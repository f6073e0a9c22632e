"""The service's shared state: configuration, the live pipeline, recorder, history, hub,
outputs and the replay sessions.

Built once by :func:`radar_io.service.app.build_app` (everything that can be refused
is refused here, before the server binds), started and stopped by the app's lifespan
(:meth:`ServiceState.start`, :meth:`ServiceState.stop`): the live reader thread, the sink
workers (TLM1, D/A, ASTERIX), the MQTT publisher, the recording archiver, the CAN
air-data reader and the replay sessions. Nothing opens a file, a device or a connection
before ``start``.

The live pipeline's source is fixed for the life of the service: no route changes it,
and only ``POST /api/recordings/start|stop`` changes the recorder. Replays run as
sessions of their own (:mod:`radar_io.service.sessions`).
"""

from __future__ import annotations

import asyncio
import gc
import logging
import re
import secrets
from pathlib import Path
from typing import Any

from radar_io import __version__
from radar_io.coordinates.transforms import load_site
from radar_io.decoding.biases import load_calibration
from radar_io.errors import ConfigError, NotFoundError, ValidationError
from radar_io.recording.recorder import Recorder
from radar_io.service.alarms import AlarmEngine
from radar_io.service.auth import Authenticator, JsonlLog
from radar_io.service.calibrations import CalibrationStore
from radar_io.service.clock import ClockSync
from radar_io.service.config import ServiceConfig
from radar_io.service.history import History
from radar_io.service.hub import Hub
from radar_io.service.limits import KIND_KEYS, ExpensiveLimiter
from radar_io.service.pipeline import Pipeline, Processor
from radar_io.service.sessions import ReplaySessions
from radar_io.sources import source_kind
from radar_io.wirespec.frame import load_spec

log = logging.getLogger("radar_io.service")

#: a recording or calibration id: a plain file name
ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,120}$"
ID_RE = re.compile(ID_PATTERN)


def check_id(value: str, what: str) -> str:
    """``value`` if it is a plain name; ValidationError otherwise."""
    if not ID_RE.match(value):
        raise ValidationError(f"{what} {value!r} must be a plain name (letters, digits, _ . -)")
    return value


class ServiceState:
    """Everything the routers share (``request.app.state.service``)."""

    def __init__(self, cfg: ServiceConfig) -> None:
        self.cfg = cfg
        self.token = cfg.token()
        self.auth = Authenticator(self.token, cfg.tokens_file)
        self.data_dir = Path(cfg.data_dir)
        self.data_dir.mkdir(parents=True, exist_ok=True)
        #: one record per control request (service/audit.py)
        self.audit = JsonlLog(self.data_dir / "audit" / "audit.jsonl")
        #: every annotation made through the service, whichever recording holds it
        self.annotations = JsonlLog(self.data_dir / "annotations.jsonl", max_bytes=1 << 40)
        self.spec = load_spec(cfg.spec) if cfg.spec else load_spec()
        site_path = cfg.resolved_site()
        self.site = load_site(site_path) if site_path else None
        self.cal_dir = self.data_dir / "calibrations"
        self.calibrations = CalibrationStore(self.cal_dir)
        # a bad --calibration is refused; an unreadable active.json is reported, not fatal
        cal = load_calibration(cfg.calibration) if cfg.calibration \
            else self.calibrations.load_active()
        self.history = History(int(cfg.history_mb * (1 << 20)))
        self.hub = Hub(self.history, cfg.ws_queue_size, cfg.ws_max_clients,
                       cfg.ws_batch_interval_s)
        self.recorder = Recorder(self.data_dir, self.spec, self.site, cfg.source,
                                 auto=cfg.auto_record, preroll_s=cfg.preroll_s,
                                 retry_s=cfg.retry_s,  # automatic recording: retry after a disk error
                                 low_space_bytes=int(cfg.low_space_mb * (1 << 20)),
                                 buffer_bytes=int(cfg.recording_buffer_mb * (1 << 20)))
        self.clock_sync = ClockSync()
        self.archiver: Any = None  # RecordingArchiver when archive_dir is set (started in start())
        if cfg.archive_dir:
            try:
                Path(cfg.archive_dir).mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise ConfigError(f"archive_dir: cannot create {cfg.archive_dir}: "
                                  f"{exc.strerror}") from exc
        self.runway_jobs: Any = None  # RunwayJobs, created by the runway router on first use
        #: reports, sync-event queries, downloads, series: bounded, on their own pool
        self.limits = ExpensiveLimiter({k: getattr(cfg, key) for k, key in KIND_KEYS.items()})
        #: the live pipeline: the one with the recorder, sinks, alarms, sync index and MQTT;
        #: ``serve --source replay://`` marks its messages ``"replay": true``
        ground_replay = source_kind(cfg.source) == "replay"
        self.track_params = self._track_params(cfg)
        self.live = Pipeline(cfg.source, self.spec, self.history, self.hub.publish_threadsafe,
                             recorder=self.recorder, site=self.site, calibration=cal,
                             replay=True if ground_replay else None, track=self.track_params)
        self.extra_processors: list[Processor] = []  #: shared by live and replays (stateless)
        self.replays = ReplaySessions(self._session_options, max_sessions=cfg.max_replays,
                                      idle_s=cfg.replay_idle_s, ws_queue_size=cfg.ws_queue_size,
                                      ws_max_clients=cfg.ws_max_clients,
                                      ws_batch_interval_s=cfg.ws_batch_interval_s)
        self.sinks: dict[str, Any] = {}       # name → SinkWorker (started in start())
        self._sink_defs: dict[str, Any] = {}  # name → Sink, checked now, opened by its worker
        self.air: Any = None
        #: limit alarms (``service.alarms.attach_alarms``, attached by the app)
        self.alarms: AlarmEngine | None = None
        self._setup_outputs(cfg)
        self.instance = secrets.token_hex(8)  # changes at every start: clients detect restarts
        self._shutdown: Any = None  # service.shutdown.Shutdown once a stop has begun

    def _track_params(self, cfg: ServiceConfig) -> Any:
        """The live filter's parameters: config keys, else the site, else TR-861."""
        from radar_io.tracking.tracker import TrackParams

        return TrackParams.for_site(self.site, q_mps2=cfg.track_q_mps2,
                                    sigma_range_m=cfg.track_sigma_range_m,
                                    sigma_angle_deg=cfg.track_sigma_angle_deg)

    def _warm_up_tracking(self) -> None:
        """Compile (numba) the live filter's kernels now, before the reader opens the radar,
        not on its first frame; the cost is logged."""
        from radar_io.tracking.live import warm_up

        p = self.track_params
        self.track_warm_up_s = warm_up()
        # numba and its compiled kernels add several hundred thousand long-lived objects;
        # a full garbage collection walking them all would stop every thread (the reader
        # included) for ~100 ms now and then: everything alive at start-up is frozen out of
        # the collector's generations (it is never garbage anyway)
        gc.collect()
        gc.freeze()
        log.info("tracking filter ready (q %g m²/s³, σ %g m, %g°) in %.2f s", p.q_mps2,
                 p.sigma_range_m, p.sigma_angle_deg, self.track_warm_up_s)

    def _setup_outputs(self, cfg: ServiceConfig) -> None:
        """Reference path, TLM1 / D/A sinks and CAN air data, as configured; a configuration
        that can never work is refused here, in one line."""
        from radar_io.coordinates.deviation import DeviationProcessor
        from radar_io.coordinates.reference_path import load_path

        self.path = load_path(cfg.path) if cfg.path else None
        if self.path is not None:
            if self.path.frame == "runway" and self.site is None:
                raise ConfigError("path: a runway-frame reference path needs a site (--site)")
            self.extra_processors.append(DeviationProcessor(self.path))
            self.live.processors.append(self.extra_processors[-1])
        if cfg.tlm_out and self.path is None:
            raise ConfigError("tlm_out: TLM1 carries the path deviation (dy_m, dz_m): "
                              "give a reference path (--path)")
        if cfg.da_out and self.path is None:
            raise ConfigError("da_out: D/A channels 6-7 carry the path deviation (dy_m, dz_m): "
                              "give a reference path (--path)")
        if cfg.tlm_out:
            from radar_io.encoding.tlm1 import TelemetryEncoder
            from radar_io.sinks.uplink import TelemetrySink

            enc = TelemetryEncoder(cycle_s=cfg.tlm_cycle_s or None)
            self._sink_defs["tlm"] = TelemetrySink(cfg.tlm_out, enc)
        if cfg.da_out:
            from radar_io.sinks.uplink import DASink

            self._sink_defs["da"] = DASink(cfg.da_out)
        if cfg.asterix_out:  # ASTERIX CAT048 (sinks/asterix.py)
            from radar_io.sinks.asterix import service_sink

            self._sink_defs["asterix"] = service_sink(self, cfg.asterix_out)
        self.mqtt: Any = None
        if cfg.publish:  # MQTT track, status and sync events (sinks/mqtt.py)
            from radar_io.sinks.mqtt import attach_to_service

            self.mqtt = attach_to_service(self, cfg.publish, username=cfg.mqtt_user,
                                          password=cfg.mqtt_password, ca_file=cfg.mqtt_ca_file)
        if cfg.can:
            from radar_io.sources.airdata import AirDataReader

            interface, channel = cfg.can.split(":", 1)
            self.air = AirDataReader(interface, channel, self.latest_radar, cfg.can_bitrate)

    # -- lifespan ---------------------------------------------------------------------------
    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Start the workers: sinks (they open and reopen their targets), air data, reader."""
        from radar_io.sinks.worker import SinkWorker, fan_out

        self.hub.attach(loop)
        for name, sink in self._sink_defs.items():
            self.sinks[name] = SinkWorker(name, sink)
        if self.sinks:  # the columns are built once per read for every sink
            self.live.processors.append(fan_out(list(self.sinks.values())))
        if self.air is not None:
            self.air.start()
        if self.mqtt is not None:
            self.mqtt.start()  # never waits for the broker
        if self.cfg.archive_dir:
            from radar_io.service.archiver import RecordingArchiver

            # recordings left unarchived by the last run first (listed before any can open)
            self.archiver = RecordingArchiver(self.cfg.archive_dir, self._archive_options,
                                              backlog=self.recorder.dir.glob("*.rdrlog"))
            self.recorder.on_closed = self.archiver.submit
        self._warm_up_tracking()
        self.replays.start(loop)
        self.live.start()

    @property
    def acq(self) -> Pipeline:
        """The live pipeline (its former name)."""
        return self.live

    def _archive_options(self) -> dict[str, Any]:
        """What a closed recording is archived with: the live site, spec, calibration, path."""
        return {"site": self.site, "spec": self.spec, "calibration": self.live.calibration,
                "reference_path": self.path}

    def _session_options(self) -> dict[str, Any]:
        """What a new replay session's pipeline is built with: the live spec, site,
        calibration and path deviation — none of the live outputs."""
        return {"spec": self.spec, "site": self.site, "calibration": self.live.calibration,
                "track": self.track_params, "processors": list(self.extra_processors)}

    def begin_shutdown(self) -> None:
        """The first thing of a stop (``serve`` calls it as soon as the server starts to
        stop): the reader stops and the recording is closed and fsynced, then the replay
        sessions stop, on a thread of its own, within ``shutdown_timeout_s`` (see
        :mod:`radar_io.service.shutdown`)."""
        if self._shutdown is None:
            from radar_io.service.shutdown import Shutdown

            first = [("reader", self.live.stop), ("recorder", self.recorder.close),
                     ("replay sessions", self.replays.close)]
            self._shutdown = Shutdown(self.cfg.shutdown_timeout_s, first)

    def stop(self) -> None:
        """Stop the reader and close the recording first, then the replay sessions, then stop
        archiving (the rest resumes at the next start), cancel runway jobs, stop the sinks,
        the MQTT publisher and the air-data reader — each even if one fails, all within
        ``shutdown_timeout_s``."""
        self.begin_shutdown()
        sd = self._shutdown
        steps: list[tuple[str, Any]] = []
        if self.archiver is not None:
            steps.append(("archiver", lambda: self.archiver.close(sd.left_s())))
        if self.runway_jobs is not None:  # cancel runway jobs, remove their spool files
            steps.append(("runway jobs", lambda: self.runway_jobs.close(sd.left_s())))
        steps.append(("expensive requests", self.limits.close))
        steps += [(f"sink {n}", w.close) for n, w in self.sinks.items()]
        steps += [("audit log", lambda: self.audit.close(min(2.0, sd.left_s()))),
                  ("annotations log", lambda: self.annotations.close(min(2.0, sd.left_s())))]
        if self.mqtt is not None:
            steps.append(("mqtt", self.mqtt.close))  # last word on PREFIX/status: offline
        if self.air is not None:
            steps.append(("air data", self.air.close))
        sd.finish(steps)

    # -- helpers for the routers ------------------------------------------------------------
    def latest_radar(self) -> dict[str, Any] | None:
        return self.history.latest_message

    def path_polyline(self, step_m: float = 50.0) -> dict[str, Any] | None:
        """The reference path sampled every ``step_m`` in the radar frame (for drawing)."""
        import numpy as np

        if self.path is None:
            return None
        from radar_io.coordinates.transforms import runway_to_radar

        s = np.append(np.arange(0.0, self.path.length_m, step_m), self.path.length_m)
        x, y, h = self.path.position(s)
        if self.path.frame == "runway":
            assert self.site is not None  # refused at start: a runway-frame path needs a site
            x, y, h = runway_to_radar(x, y, h, self.site)
        return {"frame": self.path.frame, "length_m": float(self.path.length_m),
                "x_m": np.round(x, 2).tolist(), "y_m": np.round(y, 2).tolist(),
                "h_m": np.round(h, 2).tolist()}

    def recording_path(self, rec_id: str) -> Path:
        """The ``.rdrlog`` of a recording id; ValidationError for a bad id, NotFoundError."""
        check_id(rec_id, "recording id")
        base = self.recorder.dir.resolve()
        p = (base / f"{rec_id}.rdrlog").resolve()
        if p.parent != base:
            raise ValidationError("path outside the data directory refused")
        if not p.is_file():
            raise NotFoundError(f"no recording {rec_id!r}")
        return p

    def status(self) -> dict[str, Any]:
        st = self.live.status()
        st.update(self.hub.stats())
        st["recording"] = self.recorder.current
        if self.archiver is not None:
            st["archive"] = self.archiver.stats()
        st["storage"] = self.recorder.storage()  # free_bytes, low_space, last_error
        st["auto_record"] = self.recorder.auto
        st["clock"] = {**self.recorder.clock_status(), "synchronized": self.clock_sync.get()}
        st["calibration"] = self.live.calibration.id
        st["calibration_error"] = self.calibrations.error  # unreadable active.json at start
        st["calibration_last_good"] = self.calibrations.last_good
        st["control_enabled"] = self.auth.enabled
        st["audit"] = {"written": self.audit.written, "dropped": self.audit.dropped,
                       "last_error": self.audit.last_error}
        st["replays"] = self.replays.brief()
        st["site"] = self.site.name if self.site else None
        st["version"] = __version__
        st["instance"] = self.instance
        st["path"] = self.cfg.path
        st["uplink"] = {k: w.stats() for k, w in self.sinks.items()}
        st["publish"] = {"mqtt": self.mqtt.stats()} if self.mqtt is not None else {}
        st["airdata"] = self.air.stats() if self.air is not None else None
        st["expensive"] = self.limits.stats()
        return st


#: the old name
Service = ServiceState
