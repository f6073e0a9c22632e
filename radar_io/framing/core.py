"""One framer core for every fixed-length, sync-word, CRC-16 frame (RDR1, TLM1).

The rules (radar-interface.md §3, applied to RDR1 and TLM1 alike):

* scan positions from the start; at a position holding the sync word with a
  whole frame behind it, check the CRC, then plausibility (unused bits zero,
  ``max_raw`` limits; TLM1 declares none); accept and jump past the frame, or
  count the failure (``crc_errors`` / ``implausible``) and slide one byte;
* every byte not part of an accepted frame counts in ``bytes_discarded``
  (bytes still waiting for more input are counted only at ``flush()``);
* ``seq_gaps`` — ONE rule for every format: the frames missing between two
  consecutive accepted frames, ``d = (seq - prev) mod 2**16``, gaps ``d - 1``
  when ``d > 0`` and **0 when ``d == 0``** (a repeated SEQ is a duplicate, not
  65 535 lost frames). A backwards step (``seq < prev``) wraps: 10 → 9 counts
  65 534.

A :class:`FrameFormat` says what a frame is (length, sync word, CRC, SEQ
position, per-word checks); it is made from an RDR1 :class:`FrameSpec` or a
TLM1 ``TelemetrySpec`` by :meth:`FrameFormat.of`. Two front ends share the
rules and the :class:`FramerStats` counters exactly, for any input and any
chunking: :class:`Framer` (frame by frame, ``bytes`` out) and
:class:`BatchFramer` (numpy, (N, L/2) native ``uint16`` words out).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from radar_io.wirespec.crc import crc_function, position_tables
from radar_io.wirespec.frame import CrcSpec, FrameSpec, load_spec


@dataclass(frozen=True)
class WordCheck:
    """Plausibility of one big-endian word: ``raw & unused_mask == 0`` and ``raw <= max_raw``."""

    offset: int
    size: int
    unused_mask: int
    max_raw: int | None


@dataclass(frozen=True)
class FrameFormat:
    """What the framer needs to know of a frame format (all offsets in bytes, big-endian)."""

    name: str
    length: int
    sync_word: int
    crc: CrcSpec
    seq_offset: int
    checks: tuple[WordCheck, ...]
    path: str = ""

    @property
    def sync_bytes(self) -> bytes:
        return self.sync_word.to_bytes(2, "big")

    @classmethod
    def of(cls, spec: Any) -> FrameFormat:
        """The format of an RDR1 ``FrameSpec``, a TLM1 ``TelemetrySpec`` or a ``FrameFormat``."""
        if isinstance(spec, FrameFormat):
            return spec
        if isinstance(spec, FrameSpec):
            seq = spec.field("seq")
            if seq.size != 2:
                raise ValueError(f"{spec.path}: the framer needs a 16-bit SEQ word")
            checks = tuple(WordCheck(f.offset, f.size, f.unused_mask, f.max_raw)
                           for f in spec.fields if f.unused_mask or f.max_raw is not None)
            return cls(spec.name, spec.length, spec.sync_word, spec.crc, seq.offset, checks,
                       spec.path)
        if hasattr(spec, "seq_offset") and hasattr(spec, "channels"):  # TLM1 TelemetrySpec
            return cls(spec.name, spec.length, spec.sync_word, spec.crc, spec.seq_offset, (),
                       spec.path)
        raise TypeError(f"no frame format in {type(spec).__name__}")


@dataclass
class FramerStats:
    """Counters of a framer (all cumulative)."""

    frames: int = 0
    crc_errors: int = 0
    implausible: int = 0
    bytes_discarded: int = 0
    seq_gaps: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class SeqCounter:
    """The one SEQ-gap rule: frames missing between consecutive accepted frames, mod 2**16;
    a repeated SEQ counts 0."""

    def __init__(self) -> None:
        self.last: int | None = None

    def gaps_scalar(self, seq: int) -> int:
        last, self.last = self.last, seq
        if last is None:
            return 0
        d = (seq - last) & 0xFFFF
        return d - 1 if d else 0

    def gaps_array(self, seq: np.ndarray) -> int:
        if seq.size == 0:
            return 0
        s = seq.astype(np.int64)
        first = int(s[0])
        gaps = 0 if self.last is None else self.gaps_scalar(first)
        d = np.diff(s) & 0xFFFF
        self.last = int(s[-1])
        # sum(d - 1 for d > 0) = sum(d) - count(d > 0)
        return gaps + int(d.sum()) - int(np.count_nonzero(d))


def _format(spec: Any) -> FrameFormat:
    return FrameFormat.of(spec if spec is not None else load_spec())


class Framer:
    """Per-frame framer: ``feed(bytes)`` returns the accepted frames as ``bytes``."""

    def __init__(self, spec: Any = None) -> None:
        self.format = fmt = _format(spec)
        self.spec = spec if spec is not None else load_spec()
        self.stats = FramerStats()
        self._buf = bytearray()
        self._sync = fmt.sync_bytes
        self._len = fmt.length
        self._crc = crc_function(fmt.crc)
        self._crc_at = fmt.crc.offset

        def shift(offset: int, size: int) -> int:  # of a word in the frame read as one integer
            return 8 * (fmt.length - offset - size)

        self._seq_shift = shift(fmt.seq_offset, 2)
        # every word's must-be-zero bits, as one mask over the whole frame
        self._unused = sum(c.unused_mask << shift(c.offset, c.size) for c in fmt.checks)
        self._limits = [(shift(c.offset, c.size), (1 << 8 * c.size) - 1, c.max_raw)
                        for c in fmt.checks if c.max_raw is not None]
        self._seq = SeqCounter()

    def plausible(self, frame: bytes) -> bool:
        """Unused bits zero and ``max_raw`` limits respected (CRC not checked here)."""
        return self._plausible(int.from_bytes(frame, "big"))

    def _plausible(self, v: int) -> bool:
        if v & self._unused:
            return False
        for shift, mask, max_raw in self._limits:  # noqa: SIM110 - per frame: no generator
            if (v >> shift) & mask > max_raw:
                return False
        return True

    def feed(self, data: bytes | bytearray | memoryview) -> list[bytes]:
        """Add received bytes; return the frames now complete and accepted, in order."""
        buf = self._buf
        buf += data
        n, L, st = len(buf), self._len, self.stats
        sync, crc, crc_at = self._sync, self._crc, self._crc_at
        # with no final XOR, running the CRC over the data *and* its CRC word yields 0
        residue_zero = self.format.crc.xor_out == 0
        out: list[bytes] = []
        pos = 0
        last = n - L  # last position with a whole frame behind it
        while pos <= last:
            i = buf.find(sync, pos, last + 2)
            if i < 0:
                break
            st.bytes_discarded += i - pos
            frame = bytes(buf[i:i + L])
            if (crc(frame) if residue_zero else
                    crc(frame[:crc_at]) ^ int.from_bytes(frame[crc_at:crc_at + 2], "big")):
                st.crc_errors += 1
            elif not self._plausible(v := int.from_bytes(frame, "big")):
                st.implausible += 1
            else:
                out.append(frame)
                st.frames += 1
                st.seq_gaps += self._seq.gaps_scalar((v >> self._seq_shift) & 0xFFFF)
                pos = i + L
                continue
            st.bytes_discarded += 1
            pos = i + 1
        if pos <= last:  # no sync word at any decidable position
            st.bytes_discarded += last + 1 - pos
            pos = last + 1
        del buf[:pos]
        return out

    def flush(self) -> list[bytes]:
        """End of stream: the bytes still waiting can never make a frame; count them discarded."""
        self.stats.bytes_discarded += len(self._buf)
        self._buf.clear()
        return []

    @property
    def pending(self) -> int:
        """Bytes held back waiting for more input."""
        return len(self._buf)


class FrameValidator:
    """Vectorised CRC and plausibility checks on frames given as native 16-bit words (N, L/2)."""

    def __init__(self, spec: Any) -> None:
        self.format = fmt = FrameFormat.of(spec)
        self.nwords = fmt.length // 2
        self._crc_word = fmt.crc.offset // 2
        # CRC-16 of a fixed-length frame is affine in its words: one table per word position
        self._c0, self._tables = position_tables(fmt.crc.poly, fmt.crc.init, fmt.crc.xor_out,
                                                 fmt.sync_word, self._crc_word)
        self._checks = [(c.offset, c.size, c.unused_mask, c.max_raw) for c in fmt.checks]

    def crc_ok(self, w: np.ndarray) -> np.ndarray:
        """CRC check of frames (N, L/2) native uint16 words whose first word is the sync."""
        acc = np.full(w.shape[0], self._c0, dtype=np.uint16)
        tmp = np.empty(w.shape[0], dtype=np.uint16)
        for k, t in enumerate(self._tables, start=1):
            t.take(w[:, k], out=tmp, mode="clip")
            acc ^= tmp
        return acc == w[:, self._crc_word]

    def plausible(self, w: np.ndarray) -> np.ndarray:
        ok = np.ones(w.shape[0], dtype=bool)
        for offset, size, unused, max_raw in self._checks:
            raw = field_raw(w, offset, size)
            if unused:
                ok &= (raw & unused) == 0
            if max_raw is not None:
                ok &= raw <= max_raw
        return ok


def field_raw(w: np.ndarray, offset: int, size: int) -> np.ndarray:
    """Raw unsigned value of a big-endian field from frames as native 16-bit words (N, L/2)."""
    if offset % 2 == 0 and size == 2:
        return w[:, offset // 2]
    if offset % 2 == 0 and size == 4:
        k = offset // 2
        return (w[:, k].astype(np.uint32) << 16) | w[:, k + 1]
    raw: np.ndarray = np.zeros(w.shape[0], dtype=np.uint32)
    for b in range(offset, offset + size):
        word = w[:, b // 2]
        byte = (word >> 8) if b % 2 == 0 else (word & 0xFF)
        raw = (raw << 8) | byte
    return raw


class BatchFramer:
    """Whole-buffer framer with the same rules and counters as :class:`Framer`, vectorised.

    ``feed(bytes)`` returns the accepted frames as an (N, L/2) ``uint16`` array
    of native-endian words (word 0 is the sync word). Clean aligned runs take a
    zero-search fast path (a block of frames back to back, checked at once);
    only a block with damage is searched byte by byte. State (the partial frame
    at the end, the last SEQ, the counters) carries across calls.
    """

    #: most frames checked per fast-path attempt (cache-sized); the attempt size
    #: starts small after a damaged stretch and doubles while frames keep passing
    BLOCK_FRAMES = 8192
    MIN_BLOCK_FRAMES = 16
    #: bytes searched per damaged-stretch window
    WINDOW_BYTES = 1 << 18

    def __init__(self, spec: Any = None) -> None:
        self.format = fmt = _format(spec)
        self.spec = spec if spec is not None else load_spec()
        self.validator = FrameValidator(fmt)
        self.stats = FramerStats()
        self._tail = b""
        self._L = fmt.length
        self._sync = fmt.sync_word
        self._seq = SeqCounter()
        self._seq_word = fmt.seq_offset // 2 if fmt.seq_offset % 2 == 0 else None
        self._seq_at = fmt.seq_offset
        self._block = self.BLOCK_FRAMES
        #: bytes fed so far: the stream offset just past the last byte given to :meth:`feed`
        self.stream_bytes = 0

    @property
    def pending(self) -> int:
        return len(self._tail)

    @property
    def pending_bytes(self) -> bytes:
        """The bytes held back waiting for more input (fewer than one frame): feeding them
        to a fresh framer puts it where this one stands (counters and SEQ memory aside)."""
        return self._tail

    def flush(self) -> np.ndarray:
        self.stats.bytes_discarded += len(self._tail)
        self._tail = b""
        return np.empty((0, self._L // 2), dtype=np.uint16)

    def feed(self, data: bytes | bytearray | memoryview) -> np.ndarray:
        """Add received bytes; return the accepted frames as (N, L/2) native uint16 words."""
        blocks = self.feed_blocks(data)
        if not blocks:
            return np.empty((0, self._L // 2), dtype=np.uint16)
        return blocks[0] if len(blocks) == 1 else np.concatenate(blocks)

    def feed_blocks(self, data: bytes | bytearray | memoryview,
                    ends: list[np.ndarray] | None = None) -> list[np.ndarray]:
        """As :meth:`feed`, but the frames come as a list of cache-sized blocks (no final copy).

        ``ends``: when given, one int64 array per block is appended to it: each frame's end
        as a stream offset (the offset just past its last byte, counted like
        :attr:`stream_bytes`), so a caller that knows where its chunks end can tell which
        chunk completed each frame.
        """
        # no copy of the input unless a partial frame waits from the last call
        buf: Any = self._tail + bytes(data) if self._tail else data
        b = np.frombuffer(buf, dtype=np.uint8)
        n, L = b.size, self._L
        base = self.stream_bytes - len(self._tail)  # stream offset of buf[0]
        self.stream_bytes = base + n
        last = n - L
        blocks: list[np.ndarray] = []
        pos = 0
        hi, lo = self._sync >> 8, self._sync & 0xFF
        val = self.validator
        # every frame-sized window of the buffer as big-endian words: row p starts at byte p
        rows = (np.ndarray((last + 1, L // 2), dtype=">u2", buffer=buf, strides=(1, 2))
                if last >= 0 else np.empty((0, L // 2), dtype=">u2"))
        while pos <= last:
            if b[pos] == hi and b[pos + 1] == lo:  # fast path: frames back to back from pos
                m = min((n - pos) // L, self._block)
                # native words in Fortran order: each word position (column) is contiguous
                w = b[pos:pos + m * L].view(">u2").reshape(m, L // 2).astype(np.uint16, order="F")
                good = (w[:, 0] == self._sync) & val.crc_ok(w) & val.plausible(w)
                k = m if good.all() else int(np.argmin(good))
                self._block = (min(2 * self._block, self.BLOCK_FRAMES) if k == m
                               else self.MIN_BLOCK_FRAMES)
                if k:
                    blocks.append(w[:k] if k < m else w)
                    if ends is not None:
                        ends.append(np.arange(1, k + 1, dtype=np.int64) * L + (base + pos))
                    pos += k * L
                    continue
            pos = self._search(b, rows, pos, min(last + 1, pos + self.WINDOW_BYTES), blocks,
                               ends, base)
        self._tail = bytes(buf[pos:])
        for w in blocks:
            self.stats.frames += w.shape[0]
            seq = (w[:, self._seq_word] if self._seq_word is not None
                   else field_raw(w, self._seq_at, 2))
            self.stats.seq_gaps += self._seq.gaps_array(seq)
        return blocks

    def _search(self, b: np.ndarray, rows: np.ndarray, pos: int, limit: int,
                blocks: list[np.ndarray], ends: list[np.ndarray] | None = None,
                base: int = 0) -> int:
        """Examine positions [pos, limit) byte by byte; return the next position to examine.

        Appends accepted frames to ``blocks`` (and their stream end offsets, ``base`` + end
        in ``b``, to ``ends`` when given) and counts errors and discarded bytes exactly as
        the per-frame framer would.
        """
        L, st = self._L, self.stats
        hi, lo = self._sync >> 8, self._sync & 0xFF
        seg = b[pos:limit + 1]
        cand = np.flatnonzero((seg[:-1] == hi) & (seg[1:] == lo)) + pos
        if cand.size == 0:
            st.bytes_discarded += limit - pos
            return limit
        w = rows[cand].astype(np.uint16, order="F")
        crc = self.validator.crc_ok(w)
        plaus = self.validator.plausible(w)
        valid = crc & plaus
        vpos = cand[valid]
        if vpos.size > 1 and np.any(np.diff(vpos) < L):
            keep = np.zeros(vpos.size, dtype=bool)
            nxt = -1
            for i, p in enumerate(vpos.tolist()):  # rare: a valid frame overlapping another
                if p >= nxt:
                    keep[i] = True
                    nxt = p + L
            accepted_mask = np.zeros(cand.size, dtype=bool)
            accepted_mask[np.flatnonzero(valid)[keep]] = True
        else:
            accepted_mask = valid
        apos = cand[accepted_mask]
        # failures count only where the scan actually visits them: not inside an accepted frame
        fail = np.flatnonzero(~valid)
        if apos.size and fail.size:
            fpos = cand[fail]
            j = np.searchsorted(apos, fpos, side="right") - 1
            fail = fail[(j < 0) | (fpos >= apos[np.maximum(j, 0)] + L)]
        n_crc = int(np.count_nonzero(~crc[fail]))
        st.crc_errors += n_crc
        st.implausible += fail.size - n_crc
        end = max(limit, int(apos[-1]) + L) if apos.size else limit
        st.bytes_discarded += end - pos - L * apos.size
        if apos.size:
            blocks.append(w[accepted_mask])
            if ends is not None:
                ends.append(apos.astype(np.int64) + (base + L))
        return end
