"""Tokens with roles, and the append-only logs of the service (audit, annotations).

Roles, each including the ones before it: ``viewer`` (read), ``operator`` (record, replay,
annotate, acknowledge alarms), ``admin`` (calibration, runway, tokens, the audit log).

The tokens file (``tokens_file``; ``radar-io token``) is JSON holding, per token, its name,
role, a public id and the scrypt hash of its secret with a salt of its own — never the
token. A token reads ``rio_<id>_<secret>``: the id picks the one entry to check, so a
request pays at most one scrypt (off the event loop), and a verified token is cached by
its SHA-256 (a fast hash) so later requests pay none. The file is re-read when it
changes (a revoke takes effect within :data:`RELOAD_S` without a restart).
``RADAR_IO_TOKEN`` / ``token_file`` keep working: that token is an admin named ``env``.

:class:`JsonlLog` appends JSON lines on a thread of its own (queue, fsync per batch,
rotation by size): a route hands it a record and never waits on the disk.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import os
import queue
import re
import secrets
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from radar_io.errors import ConfigError, StorageError, ValidationError

ROLES = ("viewer", "operator", "admin")
ROLE_RANK = {r: k for k, r in enumerate(ROLES)}
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.@-]{0,63}$"
#: scrypt cost: about 30 ms and 16 MiB per check on a small machine (RFC 7914 parameters)
SCRYPT_N, SCRYPT_R, SCRYPT_P, SCRYPT_LEN = 1 << 14, 8, 1, 32
RELOAD_S = 1.0  #: the tokens file is checked for changes at most this often
ENV_ACTOR = "env"  #: the name of the RADAR_IO_TOKEN / token_file token (admin)
_TOKEN_RE = re.compile(r"^rio_([0-9a-f]{12})_([A-Za-z0-9_-]{20,100})$")

log = logging.getLogger("radar_io.service.auth")


@dataclass(frozen=True)
class Principal:
    """Who made a request: the token's name and role."""

    actor: str
    role: str

    def allows(self, role: str) -> bool:
        return ROLE_RANK[self.role] >= ROLE_RANK[role]


def _scrypt(secret: str, salt: bytes) -> bytes:
    return hashlib.scrypt(secret.encode(), salt=salt, n=SCRYPT_N, r=SCRYPT_R, p=SCRYPT_P,
                          maxmem=64 << 20, dklen=SCRYPT_LEN)


class TokensFile:
    """The tokens file: ``{"tokens": [{"name", "role", "id", "salt", "scrypt", "created_utc"}]}``
    (salt and hash in hex); written to a temporary file and renamed, mode 0600."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)

    def entries(self) -> list[dict[str, Any]]:
        """The entries (a missing file: none); ConfigError names the file when malformed."""
        try:
            doc = json.loads(self.path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return []
        except OSError as exc:
            raise ConfigError(f"cannot read tokens file {self.path}: {exc.strerror}") from exc
        except ValueError as exc:
            raise ConfigError(f"tokens file {self.path}: not JSON ({exc})") from exc
        toks = doc.get("tokens") if isinstance(doc, dict) else None
        if not isinstance(toks, list):
            raise ConfigError(f"tokens file {self.path}: expected {{\"tokens\": [...]}}")
        for k, e in enumerate(toks):
            if not (isinstance(e, dict) and e.get("role") in ROLES
                    and all(isinstance(e.get(f), str) for f in ("name", "id", "salt", "scrypt"))):
                raise ConfigError(f"tokens file {self.path}: entry {k}: needs name, role "
                                  f"({'/'.join(ROLES)}), id, salt, scrypt")
        return toks

    def _write(self, toks: list[dict[str, Any]]) -> None:
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump({"tokens": toks}, f, indent=1)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path)
        except OSError as exc:
            raise StorageError(f"cannot write tokens file {self.path}: {exc.strerror}",
                               errno=exc.errno) from exc

    def add(self, name: str, role: str) -> str:
        """A new token for ``name`` with ``role``; returns the token (stored only hashed)."""
        if not re.match(NAME_PATTERN, name):
            raise ValidationError(f"token name {name!r}: letters, digits, _ . @ - (1-64)")
        if role not in ROLES:
            raise ValidationError(f"role {role!r}: one of {', '.join(ROLES)}")
        toks = self.entries()
        if any(e["name"] == name for e in toks):
            raise ValidationError(f"a token named {name!r} exists (revoke it first)")
        tid, secret = secrets.token_hex(6), secrets.token_urlsafe(32)
        salt = secrets.token_bytes(16)
        toks.append({"name": name, "role": role, "id": tid, "salt": salt.hex(),
                     "scrypt": _scrypt(secret, salt).hex(),
                     "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())})
        self._write(toks)
        return f"rio_{tid}_{secret}"

    def revoke(self, name: str) -> bool:
        """Remove the token named ``name``; False when there is none."""
        toks = self.entries()
        keep = [e for e in toks if e["name"] != name]
        if len(keep) == len(toks):
            return False
        self._write(keep)
        return True


class Authenticator:
    """Checks presented tokens: the environment token (admin) and the tokens file."""

    def __init__(self, env_token: str | None, tokens_file: str | None) -> None:
        self.env_token = env_token
        self.file = TokensFile(tokens_file) if tokens_file else None
        self._by_id: dict[str, dict[str, Any]] = {}
        self._stamp: tuple[int, int] | None = None
        self._checked = 0.0
        self._cache: dict[bytes, Principal] = {}  # sha256(token) → who
        self._lock = threading.Lock()
        self.limiter: Any = None  #: the scrypt checks' thread limiter (routers/deps.py)
        if self.file is not None:
            self._reload(force=True)  # a malformed file is refused at start

    @property
    def enabled(self) -> bool:
        """Whether any token can be accepted (else control is disabled)."""
        return self.env_token is not None or self.file is not None

    def _reload(self, force: bool = False) -> None:
        assert self.file is not None
        now = time.monotonic()
        if not force and now - self._checked < RELOAD_S:
            return
        self._checked = now
        try:
            st = os.stat(self.file.path)
            stamp = (st.st_mtime_ns, st.st_size)
        except OSError:
            stamp = (0, 0)
        if stamp == self._stamp and not force:
            return
        try:
            entries = self.file.entries()
        except ConfigError as exc:
            if force:
                raise
            log.error("%s; keeping the tokens read before", exc)
            return
        with self._lock:
            self._by_id = {e["id"]: e for e in entries}
            self._cache.clear()
            self._stamp = stamp

    def cached(self, token: str) -> Principal | None:
        """The principal of an already verified token (no scrypt; on the event loop: at most
        one ``stat`` of the tokens file a second, and a read of that small file when it
        changed)."""
        if self.env_token is not None and hmac.compare_digest(token.encode(),
                                                              self.env_token.encode()):
            return Principal(ENV_ACTOR, "admin")
        if self.file is not None:
            self._reload()
        return self._cache.get(hashlib.sha256(token.encode()).digest())

    def verify(self, token: str) -> Principal | None:
        """The principal of ``token`` or None; pays one scrypt when not cached (run it off
        the event loop)."""
        who = self.cached(token)
        if who is not None or self.file is None:
            return who
        m = _TOKEN_RE.match(token)
        if m is None:
            return None
        with self._lock:
            e = self._by_id.get(m.group(1))
        if e is None:
            return None
        if not hmac.compare_digest(_scrypt(m.group(2), bytes.fromhex(e["salt"])),
                                   bytes.fromhex(e["scrypt"])):
            return None
        who = Principal(e["name"], e["role"])
        with self._lock:
            if self._by_id.get(m.group(1)) is e:  # not revoked meanwhile
                self._cache[hashlib.sha256(token.encode()).digest()] = who
        return who


class JsonlLog:
    """An append-only JSON-lines log written by a thread of its own.

    :meth:`append` never blocks: it puts the record on a bounded queue (``dropped`` counts
    what a full queue refused, logged once per burst). The thread writes what is queued,
    fsyncs once per batch and rotates the file past ``max_bytes`` (``NAME.1`` … ``NAME.K``,
    ``keep`` files).
    """

    def __init__(self, path: Path, max_bytes: int = 16 << 20, keep: int = 5,
                 queue_size: int = 100_000) -> None:
        self.path = path
        self.max_bytes, self.keep = max_bytes, keep
        self._q: queue.Queue[dict[str, Any] | None] = queue.Queue(queue_size)
        self.dropped = 0
        self.written = 0
        self.last_error: str | None = None
        self._idle = threading.Condition()
        self._pending = 0
        self._thread = threading.Thread(target=self._run, name=f"log:{path.name}", daemon=True)
        self._thread.start()

    def append(self, record: dict[str, Any]) -> bool:
        """Queue ``record``; False (counted in ``dropped``) when the queue is full."""
        with self._idle:
            self._pending += 1
        try:
            self._q.put_nowait(record)
            return True
        except queue.Full:
            with self._idle:
                self._pending -= 1
            self.dropped += 1
            if self.dropped == 1 or self.dropped % 1000 == 0:
                log.error("%s: queue full, %d records dropped", self.path.name, self.dropped)
            return False

    def flush(self, timeout_s: float = 5.0) -> bool:
        """Wait (up to ``timeout_s``) until every queued record is on disk; not on the loop."""
        deadline = time.monotonic() + timeout_s
        with self._idle:
            while self._pending:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._idle.wait(left)
        return True

    def close(self, timeout_s: float = 5.0) -> None:
        self.flush(timeout_s)
        self._q.put(None)
        self._thread.join(timeout_s)

    def files(self) -> list[Path]:
        """The log's files, oldest first."""
        out = [self.path.with_name(f"{self.path.name}.{k}") for k in range(self.keep, 0, -1)]
        return [p for p in out if p.exists()] + ([self.path] if self.path.exists() else [])

    def read(self) -> Iterator[dict[str, Any]]:
        """Every record on disk, oldest first (bad lines skipped)."""
        from radar_io.sinks.ch10 import read_events_file

        for p in self.files():
            yield from read_events_file(p)

    def _rotate(self) -> None:
        for k in range(self.keep - 1, 0, -1):
            src = self.path.with_name(f"{self.path.name}.{k}")
            if src.exists():
                os.replace(src, self.path.with_name(f"{self.path.name}.{k + 1}"))
        os.replace(self.path, self.path.with_name(f"{self.path.name}.1"))

    def _run(self) -> None:
        while True:
            first = self._q.get()
            batch = [first]
            while len(batch) < 1000:
                try:
                    batch.append(self._q.get_nowait())
                except queue.Empty:
                    break
            recs = [r for r in batch if r is not None]
            if recs:
                self._write(recs)
            with self._idle:
                self._pending -= len(recs)
                self._idle.notify_all()
            if None in batch:
                return

    def _write(self, recs: list[dict[str, Any]]) -> None:
        data = b"".join((json.dumps(r, default=str) + "\n").encode() for r in recs)
        for attempt in range(3):
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                if self.path.exists() and self.path.stat().st_size + len(data) > self.max_bytes:
                    self._rotate()
                fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
                try:
                    os.write(fd, data)
                    os.fsync(fd)
                finally:
                    os.close(fd)
                self.written += len(recs)
                self.last_error = None
                return
            except OSError as exc:
                self.last_error = f"cannot write {self.path}: {exc.strerror}"
                time.sleep(0.1 * (attempt + 1))
        self.dropped += len(recs)
        log.error("%s; %d records lost", self.last_error, len(recs))
