"""The PySpark example of docs/analysis.md, run as written in local mode on the
three-recording archive of test_archive.py: its results equal the doc's DuckDB queries."""

from __future__ import annotations

import math
import re

import pytest
from conftest import ROOT, require_program
from test_archive import _doc_queries, _run, archived, campaign  # noqa: F401 (fixtures)

pytest.importorskip("pyspark", reason="pyspark is not installed (a test dependency: "
                    "pip install -e '.[test]')")


@pytest.fixture(scope="module")
def spark():
    """One local SparkSession for the module (2 threads, no UI, a JVM tuned for a short life:
    C1 JIT only, serial GC); the doc's getOrCreate() returns it."""
    require_program("java")
    from pyspark.sql import SparkSession

    s = (SparkSession.builder.master("local[2]").appName("radar-io-test")
         .config("spark.ui.enabled", "false")
         .config("spark.sql.shuffle.partitions", "4")
         .config("spark.sql.session.timeZone", "UTC")
         .config("spark.sql.adaptive.enabled", "false")
         .config("spark.ui.showConsoleProgress", "false")
         .config("spark.driver.extraJavaOptions",
                 "-XX:TieredStopAtLevel=1 -XX:+UseSerialGC -XX:CICompilerCount=1")
         .getOrCreate())
    try:
        yield s
    finally:
        s.stop()


def _doc_spark_code() -> str:
    text = (ROOT / "docs" / "analysis.md").read_text()
    section = text[text.index("## PySpark"):]
    return re.search(r"```python\n(.*?)```", section, re.DOTALL).group(1)


@pytest.fixture(scope="module")
def spark_results(spark, archived):  # noqa: F811 (the imported fixture)
    out, _ = archived
    code = _doc_spark_code()
    assert code.count('"s3a://range/archive"') == 1
    ns: dict = {}
    src = code.replace('"s3a://range/archive"', repr(str(out)))
    exec(compile(src, "analysis.md", "exec"), ns)  # the doc's own example
    return {name: [tuple(r) for r in ns[name].collect()] for name in ("runs", "bias", "crc",
                                                                         "test_points")}


def _same(spark_rows: list[tuple], duck_rows: list[tuple]) -> None:
    assert len(spark_rows) == len(duck_rows) > 0
    for s, d in zip(spark_rows, duck_rows, strict=True):
        assert len(s) == len(d)
        for a, b in zip(s, d, strict=True):
            if isinstance(b, float) or isinstance(a, float):
                assert math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9), (s, d)
            else:
                assert str(a) == str(b), (s, d)


@pytest.mark.parametrize("name, query", [("runs", "dy_dz_per_run"),
                                         ("bias", "bias_per_flight"),
                                         ("crc", "crc_errors_per_day"),
                                         ("test_points", "test_point_stats")])
def test_spark_equals_duckdb(spark_results, archived, name, query):  # noqa: F811
    out, _ = archived
    duck = _run(_doc_queries()[query], out)
    _same(spark_results[name], duck)
    if name == "runs":
        assert [r[3] for r in duck] == [1, 2, 1, 1]   # flight-1 holds two runs
