"""Output-column allocation modes of the batch decoder: same values, dtypes and counters in every mode."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from radar_io.decoding import batch_decoder
from radar_io.decoding.batch_decoder import ALLOC_MODES, column_array, decode_bytes

GOLDEN = Path(__file__).parent / "data" / "rdr1_golden.npz"


@pytest.fixture(scope="module")
def golden():
    with np.load(GOLDEN) as z:
        return {k: z[k] for k in z.files}


@pytest.mark.parametrize("mode", ALLOC_MODES)
def test_every_mode_reproduces_the_golden_decode(golden, mode, monkeypatch):
    """With the mmap threshold at 0 every column takes the mode's path (the golden input is small)."""
    monkeypatch.setattr(batch_decoder, "MMAP_BYTES", 0)
    monkeypatch.setattr(batch_decoder, "COLUMN_ALLOC", mode)
    for name in ("clean", "damaged"):
        b = decode_bytes(golden[f"input_{name}"].tobytes(), block_frames=1000)
        key = f"{name}/nocal"
        assert list(b.columns) == json.loads(str(golden[f"{key}/columns"]))
        assert b.stats == json.loads(str(golden[f"{key}/stats"]))
        for col in b.columns:
            want = golden[f"{key}/{col}"]
            assert b[col].dtype == want.dtype, col
            assert np.array_equal(b[col], want, equal_nan=want.dtype.kind == "f"), col


@pytest.mark.parametrize("mode", ALLOC_MODES)
def test_large_column_is_writable_and_keeps_its_values(mode):
    a = column_array(300_000, np.float64, mode)   # 2.3 MiB: above the mmap threshold
    assert a.shape == (300_000,) and a.dtype == np.float64 and a.flags.writeable
    a[:] = np.arange(300_000) * 0.5
    assert a[-1] == 149_999.5 and a[12345] == 6172.5


def test_unknown_mode_names_the_modes():
    with pytest.raises(ValueError, match="huge_populate"):
        column_array(10, np.float64, "hugepages")
