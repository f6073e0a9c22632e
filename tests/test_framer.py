"""Framers: any chunking gives the same frames; damaged streams are counted, skipped, never fatal."""

from __future__ import annotations

import binascii
import random

import independent
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from radar_io.framing.framers import BatchFramer, Framer


def rdr1_implausible(fr: bytes) -> bool:
    """§3: unused bits of the 12-bit servo errors set, or TOD not below 24 h."""
    return bool(fr[10] & 0xF0 or fr[14] & 0xF0 or fr[18] & 0xF0
                or int.from_bytes(fr[4:8], "big") >= 864_000_000)


def reference(data: bytes, sync: bytes = b"\xeb\x90", length: int = 24,
              implausible=rdr1_implausible) -> tuple[list[bytes], dict[str, int]]:
    """The framing rules of radar-interface.md §3, byte by byte, as plainly as possible.

    Defaults: RDR1. The CRC is the last two bytes, over everything before them; SEQ is bytes 2-3.
    """
    frames, st, pos, last = [], {"frames": 0, "crc_errors": 0, "implausible": 0, "bytes_discarded": 0,
                                     "seq_gaps": 0}, 0, None
    while pos + length <= len(data):
        fr = data[pos:pos + length]
        if fr[:2] != sync:
            st["bytes_discarded"] += 1
            pos += 1
            continue
        if binascii.crc_hqx(fr[:-2], 0xFFFF) != int.from_bytes(fr[-2:], "big"):
            st["crc_errors"] += 1
        elif implausible(fr):
            st["implausible"] += 1
        else:
            frames.append(fr)
            st["frames"] += 1
            seq = int.from_bytes(fr[2:4], "big")
            if last is not None and (seq - last) % 65536:
                st["seq_gaps"] += (seq - last) % 65536 - 1
            last = seq
            pos += length
            continue
        st["bytes_discarded"] += 1
        pos += 1
    st["bytes_discarded"] += len(data) - pos
    return frames, st


def run_per_frame(data: bytes, sizes) -> tuple[list[bytes], dict[str, int]]:
    f, out, pos = Framer(), [], 0
    for n in sizes:
        out += f.feed(data[pos:pos + n])
        pos += n
    out += f.feed(data[pos:])
    f.flush()
    return out, f.stats.as_dict()


def run_batch(data: bytes, sizes) -> tuple[list[bytes], dict[str, int]]:
    f, out, pos = BatchFramer(), [], 0
    for n in [*sizes, len(data)]:
        w = f.feed(data[pos:pos + n])
        pos += n
        out += [r.astype(">u2").tobytes() for r in w]
    f.flush()
    return out, f.stats.as_dict()


def stream(n: int, seq0: int = 0, seed: int = 0) -> list[bytes]:
    rng = random.Random(seed)
    return [independent.frame(seq=(seq0 + i) & 0xFFFF, tod=i * 10, sr=rng.randrange(65536),
                              dsr=rng.randrange(4096), el=rng.randrange(-32768, 32768),
                              dele=rng.randrange(4096), az=rng.randrange(65536),
                              daz=rng.randrange(4096), sts=rng.randrange(65536)) for i in range(n)]


def damage(data: bytes, seed: int, flips: int, drops: int, inserts: int, garbage: int) -> bytes:
    rng = random.Random(seed)
    b = bytearray(data)
    if not b:
        return bytes(rng.randrange(256) for _ in range(garbage))
    for _ in range(flips):
        i = rng.randrange(len(b))
        b[i] ^= 1 << rng.randrange(8)
    for _ in range(drops):
        if b:
            del b[rng.randrange(len(b))]
    for _ in range(inserts):
        b.insert(rng.randrange(len(b) + 1), rng.randrange(256))
    for _ in range(garbage):  # runs of junk, some containing sync words
        i = rng.randrange(len(b) + 1)
        junk = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 60)))
        b[i:i] = junk.replace(b"\x00\x00", b"\xeb\x90")
    return bytes(b)


def chunk_sizes(total: int, seed: int, mean: int) -> list[int]:
    rng = random.Random(seed)
    sizes, s = [], 0
    while s < total:
        n = rng.randint(0, 2 * mean)
        sizes.append(n)
        s += n
    return sizes


damaged_streams = st.builds(
    lambda n, seed, f, d, i, g: damage(b"".join(stream(n, seed=seed)), seed, f, d, i, g),
    st.integers(0, 120), st.integers(0, 10_000), st.integers(0, 30), st.integers(0, 10),
    st.integers(0, 10), st.integers(0, 10))


@pytest.mark.slow
@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(damaged_streams, st.integers(0, 1000), st.sampled_from([1, 7, 24, 25, 100, 5000]))
def test_both_framers_match_the_reference_under_any_chunking(data, seed, mean):
    want = reference(data)
    sizes = chunk_sizes(len(data), seed, mean)
    assert run_per_frame(data, sizes) == want
    assert run_batch(data, sizes) == want


@pytest.mark.parametrize("chunk", [1, 2, 3, 23, 24, 25, 4096, 10**7])
def test_every_fixed_chunking_yields_the_same_frames(chunk):
    frames = stream(300, seed=chunk)
    data = damage(b"".join(frames), chunk, 20, 3, 3, 5)
    want = reference(data)
    sizes = [chunk] * (len(data) // chunk + 1)
    assert run_per_frame(data, sizes) == want
    assert run_batch(data, sizes) == want


def test_clean_stream_megabytes_in_one_go_and_byte_by_byte():
    frames = stream(5000, seq0=65000)  # crosses the SEQ wrap
    data = b"".join(frames)
    out, st = run_batch(data, [])
    assert out == frames
    assert st == {"frames": 5000, "crc_errors": 0, "implausible": 0, "bytes_discarded": 0, "seq_gaps": 0}
    out1, st1 = run_per_frame(data[:24 * 300], [1] * (24 * 300))
    assert out1 == frames[:300] and st1["frames"] == 300 and st1["bytes_discarded"] == 0


def test_garbage_between_frames_is_counted_exactly():
    frames = stream(50)
    junk = [bytes([0x11] * k) for k in range(50)]  # no 0xEB anywhere in the junk
    data = b"".join(j + f for j, f in zip(junk, frames, strict=True)) + b"\x22" * 7
    for run in (run_per_frame, run_batch):
        out, st = run(data, [37] * 200)
        assert out == frames
        assert st["bytes_discarded"] == sum(map(len, junk)) + 7
        assert st["crc_errors"] == 0 and st["seq_gaps"] == 0


def test_bit_flipped_frame_is_a_crc_error_and_a_seq_gap():
    frames = [independent.frame(seq=i, sr=0x1111, sts=5) for i in range(10)]
    bad = bytearray(frames[4])
    bad[9] ^= 0x08
    data = b"".join(frames[:4]) + bytes(bad) + b"".join(frames[5:])
    for run in (run_per_frame, run_batch):
        out, st = run(data, [])
        assert out == frames[:4] + frames[5:]
        assert st == {"frames": 9, "crc_errors": 1, "implausible": 0, "bytes_discarded": 24, "seq_gaps": 1}


def test_truncated_frame_then_resync():
    frames = [independent.frame(seq=i, sr=0x1111, sts=5) for i in range(6)]
    data = b"".join(frames[:3]) + frames[3][:10] + b"".join(frames[4:])
    for run in (run_per_frame, run_batch):
        out, st = run(data, [5] * 100)
        assert out == frames[:3] + frames[4:]
        assert st["bytes_discarded"] == 10 and st["crc_errors"] == 1 and st["seq_gaps"] == 1


def test_truncated_stream_end_is_discarded_at_flush():
    frames = stream(3)
    data = b"".join(frames) + frames[0][:20]
    f = Framer()
    assert f.feed(data) == frames
    assert f.pending == 20 and f.stats.bytes_discarded == 0
    f.flush()
    assert f.stats.bytes_discarded == 20
    b = BatchFramer()
    assert b.feed(data).shape[0] == 3 and b.pending == 20
    b.flush()
    assert b.stats.bytes_discarded == 20


@pytest.mark.parametrize("seqs,gaps", [([65534, 65535, 0, 1], 0), ([65535, 2], 2), ([5, 5, 6], 0),
                                       ([10, 9], 65534), ([0, 100], 99)])
def test_seq_gaps_modulo_2_16(seqs, gaps):
    data = b"".join(independent.frame(seq=s) for s in seqs)
    for run in (run_per_frame, run_batch):
        assert run(data, [])[1]["seq_gaps"] == gaps


@pytest.mark.parametrize("kw", [{"dsr": 0x1800}, {"dele": 0xF800}, {"daz": 0x2000},
                                {"tod": 864_000_000}, {"tod": 0xFFFFFFFF}])
def test_crc_valid_but_implausible_frames_are_rejected_and_counted(kw):
    good = [independent.frame(seq=i) for i in range(3)]
    data = good[0] + independent.frame(seq=1, **kw) + good[1] + good[2]
    for run in (run_per_frame, run_batch):
        out, st = run(data, [])
        assert out == [good[0], good[1], good[2]]
        assert st["implausible"] == 1 and st["crc_errors"] == 0 and st["bytes_discarded"] == 24


def test_plausibility_never_rejects_a_valid_frame():
    """Extremes of every word, every status bit (reserved ones included) are accepted."""
    frames = [independent.frame(seq=s, tod=t, sr=v, dsr=e, el=a, dele=e, az=v, daz=e, sts=sts)
              for s, t, v, e, a, sts in [(0, 0, 0, 0, -32768, 0), (65535, 863_999_999, 65535, 4095,
                                                                   32767, 0xFFFF)]]
    for run in (run_per_frame, run_batch):
        assert run(b"".join(frames), [])[0] == frames


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=3000), st.integers(1, 64))
def test_random_bytes_never_raise_and_agree(data, chunk):
    sizes = [chunk] * (len(data) // chunk + 1)
    want = reference(data)
    assert run_per_frame(data, sizes) == want
    assert run_batch(data, sizes) == want


def test_false_sync_inside_a_valid_frame_is_not_counted():
    """A sync pattern inside an accepted frame is never examined."""
    fr = independent.frame(seq=1, sr=0xEB90, el=-0x146F, az=0xEB90)
    assert fr.count(b"\xeb\x90") >= 3
    for run in (run_per_frame, run_batch):
        out, st = run(fr * 20, [])
        assert len(out) == 20 and st["crc_errors"] == 0 and st["bytes_discarded"] == 0


def test_batch_framer_large_damaged_stream_matches_per_frame():
    from radar_io.benchmarks.core import corrupt_bytes

    data = corrupt_bytes(b"".join(stream(20000, seed=3)), 0.01)
    a, b = run_per_frame(data, [4096] * 200), run_batch(data, [1 << 16] * 20)
    assert a == b
    assert a[1]["frames"] > 0.7 * 20000 and a[1]["crc_errors"] > 1000
    assert np.all([len(f) == 24 for f in a[0]])


@pytest.mark.slow
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(damaged_streams, st.integers(1, 97), st.integers(1, 9), st.integers(0, 1000))
def test_batch_framer_window_and_block_boundaries(data, window, block, seed):
    """Tiny search windows and fast-path blocks put every boundary inside frames."""

    class Small(BatchFramer):
        WINDOW_BYTES = window
        BLOCK_FRAMES = block
        MIN_BLOCK_FRAMES = 1

    f, out, pos = Small(), [], 0
    for n in [*chunk_sizes(len(data), seed, 40), len(data)]:
        out += [r.astype(">u2").tobytes() for r in f.feed(data[pos:pos + n])]
        pos += n
    f.flush()
    assert (out, f.stats.as_dict()) == reference(data)


# ---------------------------------------------------------------- TLM1 through the same core
def tlm_frame(seq: int, words: tuple[int, ...] = (0,) * 10) -> bytes:
    """A TLM1 frame typed in from radar-interface.md §8: SYNC 0x1ACF, SEQ, 10 x i16, CRC-16."""
    body = b"\x1a\xcf" + seq.to_bytes(2, "big") + b"".join(
        (w & 0xFFFF).to_bytes(2, "big") for w in words)
    return body + binascii.crc_hqx(body, 0xFFFF).to_bytes(2, "big")


def tlm_reference(data: bytes) -> tuple[list[bytes], dict[str, int]]:
    """§3's rules for TLM1: a 26-byte frame, sync 0x1ACF, no plausibility limits."""
    return reference(data, b"\x1a\xcf", 26, lambda fr: False)


@pytest.mark.parametrize("seqs,gaps", [([7, 7, 8], 0), ([65535, 65535, 0], 0), ([3, 3, 3, 3], 0),
                                       ([65535, 2], 2), ([10, 9], 65534)])
def test_tlm1_uses_the_rdr1_seq_gap_rule(seqs, gaps):
    """A repeated SEQ is a duplicate (0 gaps) for TLM1 too — it used to count 65 535."""
    from radar_io.encoding.tlm1 import TelemetryDecoder

    data = b"".join(tlm_frame(s) for s in seqs)
    dec = TelemetryDecoder()
    cols = dec.feed(data)
    assert cols["seq"].tolist() == seqs
    assert dec.stats["seq_gaps"] == gaps == tlm_reference(data)[1]["seq_gaps"]
    rdr = b"".join(independent.frame(seq=s) for s in seqs)
    assert run_per_frame(rdr, [])[1]["seq_gaps"] == gaps


@pytest.mark.slow
@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 80), st.integers(0, 10_000), st.integers(0, 30), st.integers(0, 8),
       st.integers(0, 8), st.integers(0, 8), st.integers(1, 60))
def test_tlm1_both_front_ends_match_the_reference(n, seed, flips, drops, inserts, garbage, mean):
    from radar_io.encoding.tlm1 import TelemetryDecoder, load_tlm_spec

    rng = random.Random(seed)
    frames = [tlm_frame((seed + i // 3 * 2) & 0xFFFF,   # repeated and skipped SEQs
                        tuple(rng.randrange(-32768, 32768) for _ in range(10))) for i in range(n)]
    data = damage(b"".join(frames), seed, flips, drops, inserts, garbage).replace(
        b"\xeb\x90", b"\x1a\xcf")                        # junk sync words of this format
    want = tlm_reference(data)
    sizes = chunk_sizes(len(data), seed, mean)
    spec = load_tlm_spec()
    f, out, pos = Framer(spec), [], 0
    for k in [*sizes, len(data)]:
        out += f.feed(data[pos:pos + k])
        pos += k
    f.flush()
    assert (out, f.stats.as_dict()) == want
    dec, pos, seqs = TelemetryDecoder(spec), 0, []
    for k in [*sizes, len(data)]:
        seqs += dec.feed(data[pos:pos + k])["seq"].tolist()
        pos += k
    dec.flush()
    assert dec.stats == want[1]
    assert seqs == [int.from_bytes(fr[2:4], "big") for fr in want[0]]


@pytest.mark.parametrize("poly,init,xor_out", [(0x1021, 0xFFFF, 0), (0x8005, 0x0000, 0xFFFF),
                                                (0x3D65, 0x1234, 0x00FF)])
def test_affine_crc_tables_match_the_bytewise_crc(poly, init, xor_out):
    """crc = c0 ^ T_1[w_1] ^ … ^ T_10[w_10] equals the byte-by-byte CRC (binascii for CCITT)."""
    from radar_io.wirespec.crc import crc_function, position_tables
    from radar_io.wirespec.frame import CrcSpec

    crc = crc_function(CrcSpec("x", 16, poly, init, False, False, xor_out, 0, 22))
    c0, tables = position_tables(poly, init, xor_out, 0xEB90, 11)
    rng = np.random.default_rng(poly)
    w = rng.integers(0, 65536, (500, 11), dtype=np.uint16)
    w[:, 0] = 0xEB90
    acc = np.full(500, c0, dtype=np.uint16)
    for k, t in enumerate(tables, start=1):
        acc ^= t[w[:, k]]
    want = [crc(row.astype(">u2").tobytes()) for row in w]
    assert acc.tolist() == want
    if poly == 0x1021 and init == 0xFFFF:
        assert want == [binascii.crc_hqx(row.astype(">u2").tobytes(), 0xFFFF) for row in w]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(damaged_streams, st.integers(0, 1000), st.sampled_from([1, 7, 24, 100]),
       st.sampled_from([1, 3, 50]))
def test_batch_frame_ends_name_the_chunk_that_completed_each_frame(data, seed, mean, group):
    """``feed_blocks(…, ends)`` over pieces of several chunks: each end offset points just
    past the frame's bytes, and maps to the chunk after which the per-frame framer, fed
    chunk by chunk, gave that frame."""
    sizes = chunk_sizes(len(data), seed, mean)
    cuts = np.cumsum(sizes)
    per_frame, owner, fr, pos = [], [], Framer(), 0
    for k, n in enumerate(sizes):
        got = fr.feed(data[pos:pos + n])
        per_frame += got
        owner += [k] * len(got)
        pos += n
    bf, frames, ends, pos = BatchFramer(), [], [], 0
    for g in range(0, len(sizes), group):  # several chunks per feed, as the index does
        n = int(sum(sizes[g:g + group]))
        blocks = bf.feed_blocks(data[pos:pos + n], ends)
        frames += [b.astype(">u2").tobytes() for blk in blocks for b in blk]
        pos += n
    end = np.concatenate(ends) if ends else np.empty(0, np.int64)
    assert frames == per_frame and bf.stream_bytes == len(data)
    assert [data[e - 24:e] for e in end.tolist()] == per_frame
    assert np.searchsorted(cuts, end, side="left").tolist() == owner
