"""The layout's promises: a cheap ``import radar_io``, no import cycles, registries that
open what they name."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import radar_io
from radar_io.errors import RadarIOError, SourceError, ValidationError
from radar_io.sinks import SINKS, open_sink, sink_class
from radar_io.sources import SOURCES, open_source, scheme_of

PKG = Path(radar_io.__file__).resolve().parent


def test_import_radar_io_loads_no_heavy_library():
    code = ("import sys, radar_io; heavy = ('fastapi', 'cv2', 'cantools', 'pyproj', 'can', "
            "'matplotlib', 'pyarrow', 'paho'); print([m for m in heavy if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_lazy_attributes_resolve_and_unknown_names_fail():
    from radar_io.decoding import decoders

    assert radar_io.decode_bytes is decoders.decode_bytes
    assert radar_io.decode_bytes.__module__ == "radar_io.decoding.batch_decoder"
    assert issubclass(radar_io.SourceError, radar_io.RadarIOError)
    with pytest.raises(AttributeError):
        radar_io.no_such_name  # noqa: B018


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _top_level_imports(path: Path) -> set[str]:
    """radar_io modules imported at module level (imports inside functions are lazy)."""
    tree = ast.parse(path.read_text())
    found: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.If):  # TYPE_CHECKING blocks never run
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("radar_io"):
            found.add(node.module)
            for alias in node.names:  # "from radar_io.x import module"
                found.add(f"{node.module}.{alias.name}")
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("radar_io"))
    return found


def test_no_import_cycle_inside_the_package():
    modules = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph = {m: {i for i in _top_level_imports(p) if i in modules and i != m}
             for m, p in modules.items()}
    # importing a.b.c also imports the packages a and a.b
    for m in list(graph):
        for dep in list(graph[m]):
            parts = dep.split(".")
            graph[m] |= {".".join(parts[:k]) for k in range(2, len(parts))} - {m}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for d in sorted(graph[m]):
            if state.get(d) == 1 and not m.startswith(d + "."):
                cycle = [*stack[stack.index(d):], d]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if d not in state:
                visit(d)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_source_registry_by_scheme(tmp_path):
    assert scheme_of("sim://?rate_hz=10") == "sim"
    assert scheme_of("/dev/ttyUSB0?baudrate=9600") == ""
    src = open_source("sim://?rate_hz=2000&seed=4")
    assert type(src).__module__ == SOURCES["sim"].split(":")[0]
    src.open()
    try:
        data = b""
        for _ in range(20):
            data += src.read(0.05)
            if len(data) >= 48:
                break
        assert radar_io.decode_bytes(data).stats["frames"] >= 1
    finally:
        src.close()
    loop = open_source("loop://")          # no scheme of ours: pyserial handles it
    assert type(loop).__name__ == "SerialSource"
    with pytest.raises(SourceError):
        open_source("")
    with pytest.raises(RadarIOError, match=r"not found|cannot open|No such"):
        open_source(f"replay://{tmp_path}/missing.rdrlog")


def test_sink_registry_opens_every_kind(tmp_path):
    for kind in ("tlm1", "da"):
        out = tmp_path / f"x.{kind}"
        sink = open_sink(kind, str(out))
        sink.close()
        assert out.exists() and sink_class(kind).__module__ == SINKS[kind].split(":")[0]
    ch10 = open_sink("ch10", str(tmp_path / "x.ch10"))   # received chunks, not decoded rows
    ch10.write({"t_ns": np.array([10**18]), "mono_ns": np.array([5 * 10**9]),
                "data": np.array([b"\xeb\x90"], dtype=object)})
    ch10.close()
    assert (tmp_path / "x.ch10").read_bytes()[:2] == b"\x25\xeb"    # 0xEB25, little-endian
    with pytest.raises(ValidationError, match="unknown sink kind 'nope'"):
        open_sink("nope", "x")
