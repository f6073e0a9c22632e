"""Output-column allocation modes of the batch decoder: same values, dtypes and counters in every mode."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_golden

from radar_io.decoding import batch_decoder
from radar_io.decoding.batch_decoder import ALLOC_MODES, column_array, decode_bytes
from radar_io.errors import ConfigError


@pytest.mark.parametrize("mode", ALLOC_MODES)
def test_every_mode_reproduces_the_golden_decode(golden, mode, monkeypatch):
    """With the mmap threshold at 0 every column takes the mode's path (the golden input is small)."""
    monkeypatch.setattr(batch_decoder, "MMAP_BYTES", 0)
    monkeypatch.setattr(batch_decoder, "COLUMN_ALLOC", mode)
    for name in ("clean", "damaged"):
        b = decode_bytes(golden[f"input_{name}"].tobytes(), block_frames=1000)
        assert_golden(b, golden, f"{name}/nocal")


@pytest.mark.parametrize("mode", ALLOC_MODES)
def test_large_column_is_writable_and_keeps_its_values(mode):
    a = column_array(300_000, np.float64, mode)   # 2.3 MiB: above the mmap threshold
    assert a.shape == (300_000,) and a.dtype == np.float64 and a.flags.writeable
    a[:] = np.arange(300_000) * 0.5
    assert a[-1] == 149_999.5 and a[12345] == 6172.5


def test_unknown_mode_is_one_line_naming_the_setting_and_the_modes():
    with pytest.raises(ConfigError, match=r"RADAR_IO_COLUMN_ALLOC.*huge_populate") as e:
        column_array(10, np.float64, "hugepages")
    assert "\n" not in str(e.value)


@pytest.mark.slow
def test_environment_chooses_the_mode_in_a_fresh_process(tmp_path):
    """``RADAR_IO_COLUMN_ALLOC`` is read at import; the decode is the same with huge pages."""
    import os
    import subprocess
    import sys

    root = str(Path(__file__).resolve().parents[1])
    code = ("from radar_io.decoding import batch_decoder as b\n"
            "import numpy as np\n"
            "print(b.COLUMN_ALLOC)\n"
            "c = b.column_array(1 << 18, np.float64); c[:] = 2.0; print(float(c.sum()))\n")
    env = {**os.environ, "PYTHONPATH": root, "RADAR_IO_COLUMN_ALLOC": "huge_populate"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         timeout=120, check=True).stdout.split()
    assert out == ["huge_populate", str(2.0 * (1 << 18))]


@pytest.mark.parametrize("inner", [7, 1000, 4096, 16384])
def test_inner_step_size_does_not_change_a_value(golden, inner, monkeypatch):
    """``BatchDecoder.BLOCK`` (frames per inner step) is a speed knob only."""
    monkeypatch.setattr(batch_decoder.BatchDecoder, "BLOCK", inner)
    b = decode_bytes(golden["input_damaged"].tobytes())
    assert b.stats == json.loads(str(golden["damaged/nocal/stats"]))
    for col in b.columns:
        want = golden[f"damaged/nocal/{col}"]
        assert np.array_equal(b[col], want, equal_nan=want.dtype.kind == "f"), col
