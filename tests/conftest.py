from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared"
sys.path.insert(0, str(Path(__file__).resolve().parent))


@pytest.fixture(scope="session")
def spec():
    from radar_io.wirespec.frame import load_spec

    return load_spec()


@pytest.fixture(scope="session")
def vectors() -> dict:
    path = SHARED / "vectors" / "rdr1_vectors.json"
    return json.loads(path.read_text())


def run_cli(*args: str, input: bytes | None = None, timeout: float = 300,
            env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run ``radar-io`` as a separate process, the way an operator would."""
    return subprocess.run([sys.executable, "-m", "radar_io.cli", *args], input=input,
                          capture_output=True, timeout=timeout, cwd=ROOT,
                          env={**os.environ, **(env or {})})
