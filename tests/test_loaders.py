"""Every file loader refuses malformed input with ONE line naming the file and the field.

One table, :data:`CASES`, drives three checks: the loader raises a ValidationError whose
message names the file and the field; the ``radar-io`` command that reads that kind of
file exits with code 2 printing exactly that one line; and ``docs/input-validation.md``
is the table rendered (regenerate with ``python tests/test_loaders.py``).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

import independent  # noqa: E402

from radar_io.errors import ValidationError  # noqa: E402

DOC = ROOT / "docs" / "input-validation.md"

SITE_OK = (ROOT / "firmware_specs" / "sites" / "demo.toml").read_text(encoding="utf-8")
DBC_OK = (ROOT / "firmware_specs" / "airdata.dbc").read_text(encoding="utf-8")
SITE_MIN = ('[radar]\nlat_deg = 35.0\nlon_deg = 139.0\nh_m = 10.0\n'
            '[runway]\nheading_deg = 340.0\nradar_xr_m = 0.0\nradar_yr_m = 0.0\nradar_hr_m = 0.0\n')
PT = "[[points]]\nx_m = {x}\ny_m = 0.0\nh_m = 100.0\n"
PATH_OK = 'frame = "radar"\nturn_radius_m = 1000.0\n' + PT.format(x=0.0) + PT.format(x=5000.0)
CAL_OK = {"format": "radar_io-calibration/1", "id": "t", "biases": {"dsr_m": 1.0, "del_deg": 0.01,
                                                                     "daz_deg": -0.02}}
CSV_HEAD = "group,radar_sr_m,radar_el_deg,radar_az_deg,photo_sr_m,photo_el_deg,photo_az_deg\n"
CSV_ROW = "A,1000,1.0,10.0,1001,1.01,10.02\n"


def cal(**top) -> str:
    return json.dumps({**CAL_OK, **top})


def bias(**b) -> str:
    return json.dumps({**CAL_OK, "biases": {**CAL_OK["biases"], **b}})


@dataclass(frozen=True)
class Case:
    kind: str            #: site | path | calibration | dbc | points
    label: str           #: what is wrong, in words
    content: bytes | str
    expect: str          #: the part of the message that names the field / the problem


CASES: list[Case] = [
    # ---- site TOML ---------------------------------------------------------------------
    Case("site", "empty file", "", "is empty"),
    Case("site", "binary file", b"\x7fELF\x02\x01\x01\x00\x00", "is a binary file"),
    Case("site", "not UTF-8", b"name = \"caf\xe9\"\n", "is not UTF-8 text"),
    Case("site", "not TOML", "[radar\n", "is not valid TOML"),
    Case("site", "missing section", "name = 'x'\n", "field radar: missing"),
    Case("site", "section is a number", "radar = 3\n[runway]" + SITE_MIN.split("[runway]")[1],
         "field radar: expected a table"),
    Case("site", "missing field", SITE_MIN.replace("lon_deg = 139.0\n", ""),
         "field radar.lon_deg: missing"),
    Case("site", "string for a number", SITE_MIN.replace("h_m = 10.0", "h_m = '10'"),
         "field radar.h_m: expected a number, got a string"),
    Case("site", "boolean for a number", SITE_MIN.replace("lat_deg = 35.0", "lat_deg = true"),
         "field radar.lat_deg: expected a number, got a boolean"),
    Case("site", "latitude out of range", SITE_MIN.replace("lat_deg = 35.0", "lat_deg = 95.0"),
         "field radar.lat_deg: 95.0 is out of range -90 .. 90"),
    Case("site", "NaN", SITE_MIN.replace("lon_deg = 139.0", "lon_deg = nan"),
         "field radar.lon_deg: expected a finite number"),
    Case("site", "heading out of range", SITE_MIN.replace("heading_deg = 340.0", "heading_deg = 400"),
         "field runway.heading_deg: 400 is out of range"),
    Case("site", "unknown section", SITE_MIN + "[radr]\nx = 1\n", "field radr: unknown key"),
    Case("site", "unknown field (typo)", SITE_MIN.replace("radar_hr_m", "radar_h_m"),
         "field runway.radar_h_m: unknown key"),
    Case("site", "name not a string", "name = 5\n" + SITE_MIN, "field name: expected a string"),
    Case("site", "ASTERIX SAC out of range", SITE_MIN + "[asterix]\nsac = 256\nsic = 1\n",
         "field asterix.sac: 256 is out of range 0 .. 255"),
    Case("site", "ASTERIX SIC not an integer", SITE_MIN + "[asterix]\nsac = 0\nsic = 1.5\n",
         "field asterix.sic: expected an integer, got a number"),
    Case("site", "ASTERIX SIC missing", SITE_MIN + "[asterix]\nsac = 0\n", "field asterix.sic: missing"),
    Case("site", "tracker range σ not positive",
         SITE_MIN.replace("h_m = 10.0\n", "h_m = 10.0\nsigma_range_m = 0.0\n"),
         "field radar.sigma_range_m: 0.0 must be greater than 0.0"),
    # ---- reference path TOML -----------------------------------------------------------
    Case("path", "empty file", "  \n", "is empty"),
    Case("path", "binary file", b"\x00\x01\x02frame", "is a binary file"),
    Case("path", "frame is a table", PATH_OK.replace('frame = "radar"', "frame = {}"),
         "field frame: expected \"radar\" or \"runway\", got a table {}"),
    Case("path", "frame unknown", PATH_OK.replace('"radar"', '"geodetic"'),
         "field frame: expected 'radar' or 'runway', got 'geodetic'"),
    Case("path", "frame missing", PATH_OK.replace('frame = "radar"\n', ""), "field frame: missing"),
    Case("path", "turn radius zero", PATH_OK.replace("1000.0", "0.0"),
         "field turn_radius_m: 0.0 must be greater than 0.0"),
    Case("path", "turn radius a string", PATH_OK.replace("1000.0", '"big"'),
         "field turn_radius_m: expected a number, got a string"),
    Case("path", "points not an array", 'frame = "radar"\nturn_radius_m = 1.0\npoints = 3\n',
         "field points: expected an array of tables, got a number"),
    Case("path", "point not a table", 'frame = "radar"\nturn_radius_m = 1.0\npoints = [1, 2]\n',
         "field points[0]: expected a table, got a number"),
    Case("path", "one point only", 'frame = "radar"\nturn_radius_m = 1.0\n' + PT.format(x=0.0),
         "field points: expected at least 2 entries, got 1"),
    Case("path", "point missing a field", PATH_OK.replace("x_m = 5000.0\ny_m = 0.0\nh_m = 100.0",
                                                          "x_m = 5000.0\ny_m = 0.0"),
         "field points[1].h_m: missing"),
    Case("path", "point coordinate infinite", PATH_OK.replace("x_m = 5000.0", "x_m = inf"),
         "field points[1].x_m: expected a finite number"),
    Case("path", "unknown point field", PATH_OK.replace("h_m = 100.0\n", "z_m = 100.0\n", 1),
         "field points[0].z_m: unknown key"),
    Case("path", "unknown top-level key", "radius = 5\n" + PATH_OK, "field radius: unknown key"),
    Case("path", "two points at one place", PATH_OK.replace("5000.0", "0.0"),
         "pass points 0 and 1 have the same horizontal position"),
    # ---- calibration set JSON ----------------------------------------------------------
    Case("calibration", "empty file", "", "is empty"),
    Case("calibration", "binary file", b"{\x00}", "is a binary file"),
    Case("calibration", "not JSON", "{biases: 1}", "is not valid JSON"),
    Case("calibration", "NaN literal", bias(dsr_m=1.0).replace("1.0", "NaN", 1),
         "NaN is not allowed"),
    Case("calibration", "nested too deeply", "[" * 100_000 + "]" * 100_000, "nested too deeply"),
    Case("calibration", "document is an array", "[1, 2]",
         "the document: expected a table of fields, got an array"),
    Case("calibration", "biases missing", json.dumps({"id": "x"}), "field biases: missing"),
    Case("calibration", "biases not an object", cal(biases="none"),
         "field biases: expected a table, got a string"),
    Case("calibration", "bias a string", bias(dsr_m="3"),
         "field biases.dsr_m: expected a number, got a string"),
    Case("calibration", "bias out of range", bias(daz_deg=720.0),
         "field biases.daz_deg: 720.0 is out of range -180.0 .. 180.0"),
    Case("calibration", "unknown bias", bias(dh_m=1.0), "field biases.dh_m: unknown key"),
    Case("calibration", "unknown top-level key", cal(bias={}), "field bias: unknown key"),
    Case("calibration", "wrong format", cal(format="radar_io-calibration/9"),
         "field format: unsupported calibration format"),
    Case("calibration", "id not a string", cal(id=7), "field id: expected a string, got a number"),
    Case("calibration", "statistics not an object", cal(statistics=[1]),
         "field statistics: expected a table, got an array"),
    # ---- DBC ---------------------------------------------------------------------------
    Case("dbc", "empty file", "\n", "is empty"),
    Case("dbc", "binary file", b"VERSION \"\"\x00\x00", "is a binary file"),
    Case("dbc", "not DBC syntax", "this is not a dbc {", "cannot be parsed"),
    Case("dbc", "message missing", DBC_OK.replace("BO_ 259 DME: 8 DAU", "BO_ 259 DMEX: 8 DAU"),
         "message DME: missing"),
    Case("dbc", "signal missing", DBC_OK.replace("SG_ ShutterTime", "SG_ ShutterTick"),
         "message SHUTTER_EVENT: missing signal(s) ShutterTime"),
    # ---- calibration point files (CSV) -------------------------------------------------
    Case("points", "empty file", "", "empty file (expected a header row)"),
    Case("points", "binary file", b"group,\x00\x01", "is a binary file"),
    Case("points", "not UTF-8", CSV_HEAD.encode() + b"\xe9,1,2,3,4,5,6\n", "is not UTF-8 text"),
    Case("points", "missing column", CSV_HEAD.replace("radar_sr_m", "radar_range") + CSV_ROW,
         "missing column(s) radar_sr_m"),
    Case("points", "value not a number", CSV_HEAD + CSV_ROW.replace("1000", "far"),
         "line 2, column radar_sr_m: expected a finite number, got 'far'"),
    Case("points", "value NaN", CSV_HEAD + CSV_ROW.replace("1.01", "nan"),
         "line 2, column photo_el_deg: expected a finite number, got 'nan'"),
    Case("points", "wrong field count", CSV_HEAD + "A,1000,1.0\n", "line 2: expected 7 fields, got 3"),
    Case("points", "duplicate column", CSV_HEAD.replace("photo_az_deg", "photo_el_deg") + CSV_ROW,
         "line 1: duplicate column(s) photo_el_deg"),
    Case("points", "header only", CSV_HEAD, "expected at least 1 data row(s), got 0"),
]
FILE_NAME = {"site": "site.toml", "path": "path.toml", "calibration": "cal.json",
             "dbc": "airdata.dbc", "points": "pairs.csv"}


def _load(kind: str) -> Callable[[Path], object]:
    if kind == "site":
        from radar_io.coordinates.transforms import load_site
        return load_site
    if kind == "path":
        from radar_io.coordinates.reference_path import load_path
        return load_path
    if kind == "calibration":
        from radar_io.decoding.biases import load_calibration
        return load_calibration
    if kind == "dbc":
        from radar_io.decoding.airdata import load_dbc
        return load_dbc
    from radar_io.calibration.tables import read_table

    def points(p: Path) -> object:
        t = read_table(p)
        t.require("group", "radar_sr_m", "radar_el_deg", "radar_az_deg")
        return [t.floats(c) for c in t.columns if c != "group"]
    return points


def _argv(kind: str, f: Path, d: Path) -> list[str]:
    """The radar-io command that reads a file of this kind."""
    empty = d / "empty.bin"
    empty.write_bytes(b"")
    out = ["-q", "-o", str(d / "out.csv")]
    if kind == "site":
        return ["decode", str(empty), *out, "--site", str(f)]
    if kind == "path":
        return ["decode", str(empty), *out, "--path", str(f)]
    if kind == "calibration":
        return ["decode", str(empty), *out, "--calibration", str(f)]
    if kind == "dbc":   # align reads the radar file first: give it frames with sync edges
        radar = d / "radar.bin"
        radar.write_bytes(b"".join(independent.frame(seq=i, tod=i * 500,
                                                     sts=(0x8000 if i % 4 < 2 else 0) | 5)
                                   for i in range(40)))
        return ["align", str(radar), str(d / "aircraft.asc"), "--dbc", str(f)]
    return ["calibrate", "bias", str(f)]


def _write(case: Case, d: Path) -> Path:
    f = d / FILE_NAME[case.kind]
    data = case.content if isinstance(case.content, bytes) else case.content.encode("utf-8")
    f.write_bytes(data)
    return f


def _message(case: Case, d: Path) -> str:
    f = _write(case, d)
    with pytest.raises(ValidationError) as exc:
        _load(case.kind)(f)
    return str(exc.value)


IDS = [f"{c.kind}-{c.label.replace(' ', '_')}" for c in CASES]


def test_good_files_load(tmp_path):
    """The table's baselines are valid, so each case fails for the one thing it changes."""
    for kind, text in (("site", SITE_OK), ("site", SITE_MIN), ("path", PATH_OK),
                       ("calibration", json.dumps(CAL_OK)), ("dbc", DBC_OK),
                       ("points", CSV_HEAD + CSV_ROW)):
        _load(kind)(_write(Case(kind, "ok", text, ""), tmp_path))


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_loader_names_file_and_field(case, tmp_path):
    msg = _message(case, tmp_path)
    assert "\n" not in msg
    assert str(tmp_path / FILE_NAME[case.kind]) in msg
    assert case.expect in msg


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_cli_exits_2_with_one_line(case, tmp_path, capsys):
    from radar_io.cli.main import main

    f = _write(case, tmp_path)
    rc = main(_argv(case.kind, f, tmp_path))
    err = capsys.readouterr().err
    assert rc == 2
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("radar-io: error: ") and str(f) in lines[0] and case.expect in lines[0]


@pytest.mark.slow
def test_cli_as_a_process_prints_no_traceback(tmp_path):
    """The operator's view: a separate process, exit code 2, one line on stderr."""
    from conftest import run_cli

    f = tmp_path / "p.toml"
    f.write_text(PATH_OK.replace('frame = "radar"', "frame = {}"))
    empty = tmp_path / "empty.bin"
    empty.write_bytes(b"")
    r = run_cli("decode", str(empty), "-q", "-o", str(tmp_path / "o.csv"), "--path", str(f))
    assert r.returncode == 2
    assert r.stderr.decode().splitlines() == [
        f'radar-io: error: path file {f}: field frame: expected "radar" or "runway", got a table {{}}']


def test_site_by_name_and_asterix(tmp_path):
    from radar_io.coordinates.transforms import load_site, site_names

    assert "demo" in site_names()
    demo = load_site("demo")
    assert demo == load_site(ROOT / "firmware_specs" / "sites" / "demo.toml")
    assert (demo.asterix_sac, demo.asterix_sic) == (0, 1)
    assert demo.to_dict()["asterix"] == {"sac": 0, "sic": 1}
    f = tmp_path / "s.toml"
    f.write_text(SITE_MIN)
    plain = load_site(f)
    assert plain.asterix_sac is None and "asterix" not in plain.to_dict()
    f.write_text(SITE_MIN + "[asterix]\nsac = 255\nsic = 0\n")
    assert (load_site(f).asterix_sac, load_site(f).asterix_sic) == (255, 0)
    with pytest.raises(ValidationError, match=r"no packaged site of that name .*demo"):
        load_site("no_such_site")


def test_cli_site_by_name(tmp_path):
    """``--site demo`` gives the same geodetic columns as the path of the packaged file."""
    from radar_io.cli.main import main

    radar = tmp_path / "r.bin"
    radar.write_bytes(b"".join(independent.frame(seq=i, sr=20000 + i, el=500, az=9000, sts=5)
                               for i in range(5)))
    outs = []
    for site in ("demo", str(ROOT / "firmware_specs" / "sites" / "demo.toml")):
        out = tmp_path / f"{len(outs)}.csv"
        assert main(["decode", str(radar), "-q", "-o", str(out), "--site", site]) == 0
        outs.append(out.read_text())
    assert outs[0] == outs[1] and "lat_deg" in outs[0].splitlines()[0]
    assert len(outs[0].splitlines()) == 6


# ---------------------------------------------------------------- the documentation table
def render_doc(tmp: Path) -> str:
    rows = []
    for c in CASES:
        d = tmp / f"{c.kind}-{len(rows)}"
        d.mkdir()
        msg = _message(c, d).replace(str(d) + "/", "")
        rows.append(f"| {c.kind} | {c.label} | `{msg.replace('|', '¦')}` |")
    return (
        "# Input validation: malformed files and their one-line errors\n\n"
        "Every file loader checks its input field by field (`radar_io.textfiles.Fields`): a\n"
        "wrong type, a missing field, a value out of range, an unknown key, an empty, binary or\n"
        "non-UTF-8 file each stop the load with ONE line that names the file and the field\n"
        "(`points[1].h_m` is the `h_m` of the second `[[points]]` table). The command line prints\n"
        "that line as `radar-io: error: ...` and exits with code 2; no traceback.\n\n"
        "Loaders: site TOML (`coordinates/transforms.load_site`, also by packaged name:\n"
        "`--site demo`), reference path TOML (`coordinates/reference_path.load_path`),\n"
        "calibration set JSON (`decoding/biases.load_calibration`), DBC\n"
        "(`decoding/airdata.load_dbc`), calibration point CSV (`calibration/tables.read_table`;\n"
        "these name line and column). Frame specs (`wirespec/`) and the service config have\n"
        "their own loaders built on the same helpers.\n\n"
        "Site files may carry an optional `[asterix]` table with `sac` and `sic`, integers\n"
        "0..255 (System Area Code and System Identification Code), exposed as\n"
        "`Site.asterix_sac` / `Site.asterix_sic`; the packaged `demo` site has `sac = 0, sic = 1`.\n\n"
        f"The table below is generated from the {len(CASES)} cases of `tests/test_loaders.py`\n"
        "(each also run through the CLI, which must exit 2 with this one line);\n"
        "regenerate it with `python tests/test_loaders.py`, and a test fails when it is stale.\n\n"
        "| file | what is wrong | message |\n| --- | --- | --- |\n" + "\n".join(rows) + "\n")


def test_doc_table_is_current(tmp_path):
    assert DOC.read_text(encoding="utf-8") == render_doc(tmp_path), \
        "docs/input-validation.md is stale: run python tests/test_loaders.py"


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as t:
        DOC.write_text(render_doc(Path(t)), encoding="utf-8")
    print(f"wrote {DOC}")


# ---------------------------------------------------------------- hermetic test harness
def test_tests_read_nothing_beside_the_repository():
    """No test refers to the shared folder next to the clone (its data is in tests/data/)."""
    import re

    bad = re.compile(r"""["'/]shared["'/]|\.\./shared|parent\s*/\s*["']shared""")
    hits = [f"{p.relative_to(ROOT)}:{i}" for p in (ROOT / "tests").rglob("*.py")
            for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
            if bad.search(line) and "bad = re.compile" not in line]
    assert not hits, hits


@pytest.mark.slow
@pytest.mark.parametrize("ci, rc", [("", 0), ("true", 1)])
def test_a_skip_fails_the_session_only_in_ci(tmp_path, ci, rc):
    """tests/conftest.py: require_program skips with the reason; with CI=true that fails the run."""
    import os
    import shutil
    import subprocess

    shutil.copy(ROOT / "tests" / "conftest.py", tmp_path / "conftest.py")
    (tmp_path / "test_needs.py").write_text(
        "from conftest import require_program\n\n"
        "def test_needs_a_program():\n    require_program('radar-io-no-such-program')\n")
    env = {**os.environ, "CI": ci}
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rs",
                        str(tmp_path)], capture_output=True, text=True, cwd=tmp_path, env=env,
                       timeout=120)
    assert r.returncode == rc, r.stdout + r.stderr
    assert "radar-io-no-such-program is not installed" in r.stdout
    assert ("skipped, which CI does not allow" in r.stdout) == bool(ci)
