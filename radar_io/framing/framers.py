"""Framers: find RDR1 frames in a byte stream (radar-interface.md §3).

Semantics, shared exactly by both framers so that they accept the same frames
and count the same errors for any input and any chunking:

* scan positions from the start; at a position holding the sync word with a
  whole frame behind it, check the CRC, then plausibility (unused bits zero,
  ``max_raw`` limits); accept and jump past the frame, or count the failure
  (``crc_errors`` / ``implausible``) and slide one byte;
* every byte not part of an accepted frame counts in ``bytes_discarded``
  (bytes still waiting for more input are counted only at :meth:`flush`);
* ``seq_gaps`` adds the frames missing between consecutive accepted frames,
  ``(seq - prev - 1) mod 2**16``; a repeated SEQ counts as no gap.

:class:`Framer` works frame by frame (live use, debugging); :class:`BatchFramer`
does the same over whole buffers with numpy and hands out the accepted frames
as an (N, L/2) array of native 16-bit words.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from radar_io.wirespec.crc import crc_function, word_table
from radar_io.wirespec.frame import FrameSpec, load_spec


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


class _SeqTracker:
    """Counts frames missing by SEQ, modulo 2**16."""

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
        prev = np.empty_like(s)
        prev[1:] = s[:-1]
        prev[0] = s[0] - 1 if self.last is None else self.last
        d = (s - prev) & 0xFFFF
        self.last = int(s[-1])
        return int(np.sum(np.where(d > 0, d - 1, 0)))


class Framer:
    """Per-frame framer: ``feed(bytes)`` returns the accepted frames as ``bytes``."""

    def __init__(self, spec: FrameSpec | None = None) -> None:
        self.spec = spec = spec or load_spec()
        self.stats = FramerStats()
        self._buf = bytearray()
        self._sync = spec.sync_bytes
        self._len = spec.length
        self._crc = crc_function(spec.crc)
        self._crc_at = spec.crc.offset
        # fields located in the frame read as one big-endian integer: (shift, mask)
        def at(f: Any) -> tuple[int, int]:
            return 8 * (spec.length - f.offset - f.size), (1 << (8 * f.size)) - 1

        self._seq_at = at(spec.field("seq"))
        # every word's must-be-zero bits, as one mask over the whole frame
        self._unused = sum(f.unused_mask << at(f)[0] for f in spec.fields)
        self._limits = [(*at(f), f.max_raw) for f in spec.fields if f.max_raw is not None]
        self._seq = _SeqTracker()

    def plausible(self, frame: bytes) -> bool:
        """Unused bits zero and ``max_raw`` limits respected (CRC not checked here)."""
        return self._plausible(int.from_bytes(frame, "big"))

    def _plausible(self, v: int) -> bool:
        if v & self._unused:
            return False
        for shift, mask, max_raw in self._limits:
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
        residue_zero = self.spec.crc.xor_out == 0
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
                shift, mask = self._seq_at
                st.seq_gaps += self._seq.gaps_scalar((v >> shift) & mask)
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
    """Vectorised CRC and plausibility checks on frames given as native 16-bit words."""

    def __init__(self, spec: FrameSpec) -> None:
        if spec.length % 2 or spec.byte_order != "big":
            raise ValueError("the batch framer needs a big-endian frame of even length")
        self.spec = spec
        self.nwords = spec.length // 2
        self._table = word_table(spec.crc.poly)
        # register after the sync word, which every candidate starts with
        self._reg0 = int(self._table[spec.crc.init ^ spec.sync_word])
        self._crc_word = spec.crc.offset // 2
        self._checks: list[tuple[int, int, int, int | None]] = []  # (word, nwords, unused, max)
        for f in spec.fields:
            if not (f.unused_mask or f.max_raw is not None):
                continue
            self._checks.append((f.offset, f.size, f.unused_mask, f.max_raw))

    def crc_ok(self, w: np.ndarray) -> np.ndarray:
        """CRC check of frames (N, L/2) native uint16 words whose first word is the sync."""
        t = self._table
        reg = np.full(w.shape[0], self._reg0, dtype=np.uint16)
        for k in range(1, self._crc_word):
            np.bitwise_xor(reg, w[:, k], out=reg)
            reg = t.take(reg, mode="clip")
        reg ^= np.uint16(self.spec.crc.xor_out)
        return reg == w[:, self._crc_word]

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
    raw = np.zeros(w.shape[0], dtype=np.uint32)
    for b in range(offset, offset + size):
        word = w[:, b // 2]
        byte = (word >> 8) if b % 2 == 0 else (word & 0xFF)
        raw = (raw << 8) | byte
    return raw


class BatchFramer:
    """Whole-buffer framer with the same semantics as :class:`Framer`, vectorised with numpy.

    ``feed(bytes)`` returns the accepted frames as an (N, L/2) ``uint16`` array
    of native-endian words (word 0 is the sync word). Clean aligned runs take a
    zero-search fast path; damaged stretches are searched byte by byte.
    """

    #: most frames checked per fast-path attempt (cache-sized); the attempt size
    #: starts small after a damaged stretch and doubles while frames keep passing
    BLOCK_FRAMES = 8192
    MIN_BLOCK_FRAMES = 16
    #: bytes searched per damaged-stretch window
    WINDOW_BYTES = 1 << 18

    def __init__(self, spec: FrameSpec | None = None) -> None:
        self.spec = spec = spec or load_spec()
        self.validator = FrameValidator(spec)
        self.stats = FramerStats()
        self._tail = b""
        self._L = spec.length
        self._sync = spec.sync_word
        self._seq = _SeqTracker()
        seq = spec.field("seq")
        self._seq_at = (seq.offset, seq.size)
        self._block = self.BLOCK_FRAMES

    @property
    def pending(self) -> int:
        return len(self._tail)

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

    def feed_blocks(self, data: bytes | bytearray | memoryview) -> list[np.ndarray]:
        """As :meth:`feed`, but the frames come as a list of cache-sized blocks (no final copy)."""
        buf = self._tail + bytes(data) if self._tail else bytes(data)
        b = np.frombuffer(buf, dtype=np.uint8)
        n, L = b.size, self._L
        last = n - L
        blocks: list[np.ndarray] = []
        pos = 0
        hi, lo = self._sync >> 8, self._sync & 0xFF
        val = self.validator
        # every frame-sized window of the buffer as big-endian words: row p starts at byte p
        rows = (np.ndarray((last + 1, L // 2), dtype=">u2", buffer=buf, strides=(1, 2))
                if last >= 0 else None)
        while pos <= last:
            if b[pos] == hi and b[pos + 1] == lo:  # fast path: frames back to back from pos
                m = min((n - pos) // L, self._block)
                w = b[pos:pos + m * L].view(">u2").reshape(m, L // 2).astype(np.uint16)
                good = (w[:, 0] == self._sync) & val.crc_ok(w) & val.plausible(w)
                k = m if good.all() else int(np.argmin(good))
                self._block = (min(2 * self._block, self.BLOCK_FRAMES) if k == m
                               else self.MIN_BLOCK_FRAMES)
                if k:
                    blocks.append(w[:k] if k < m else w)
                    pos += k * L
                    continue
            pos = self._search(b, rows, pos, min(last + 1, pos + self.WINDOW_BYTES), blocks)
        self._tail = buf[pos:]
        for w in blocks:
            self.stats.frames += w.shape[0]
            self.stats.seq_gaps += self._seq.gaps_array(field_raw(w, *self._seq_at))
        return blocks

    def _search(self, b: np.ndarray, rows: np.ndarray, pos: int, limit: int,
                blocks: list[np.ndarray]) -> int:
        """Examine positions [pos, limit) byte by byte; return the next position to examine.

        Appends accepted frames to ``blocks`` and counts errors and discarded
        bytes exactly as the per-frame framer would.
        """
        L, st = self._L, self.stats
        hi, lo = self._sync >> 8, self._sync & 0xFF
        seg = b[pos:limit + 1]
        cand = np.flatnonzero((seg[:-1] == hi) & (seg[1:] == lo)) + pos
        if cand.size == 0:
            st.bytes_discarded += limit - pos
            return limit
        w = rows[cand].astype(np.uint16)
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
        return end
