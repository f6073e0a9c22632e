"""Expensive requests without a token against a real ``radar-io serve``: a burst of flight
reports and of a recording's sync-event queries. Beyond the per-kind limit the answer is
429 with Retry-After at once; the work runs in worker processes, so ``/api/status`` and a
control call keep answering meanwhile (loose bound here; the figures: radar-io bench
--expensive-clients, docs/service.md)."""

from __future__ import annotations

import pytest

from radar_io.benchmarks.expensive import bench_expensive


@pytest.mark.parametrize("kind,clients,limit", [("report", 20, 2), ("sync", 20, 4)])
def test_a_burst_beyond_the_limit_is_429_with_retry_after(kind, clients, limit):
    res = bench_expensive(kind, clients=clients, recording_s=60.0, poll_every_s=0.05)
    answers = res["answers"]
    assert set(answers) <= {"200", "429"}, answers
    assert 1 <= answers.get("200", 0) <= limit and answers["429"] >= clients - limit
    assert res["retry_after_on_every_429"] and min(res["retry_after_s"]) >= 1
    running = res["limits"]["reports" if kind == "report" else "sync"]
    assert running["refused"] == answers["429"] and running["running"] == 0
    # the loop never waited for the work: status and control answered throughout
    assert res["status_requests"] >= 1 and res["control_requests"] >= 1
    assert res["status_p50_ms"] < 250 and res["status_max_ms"] < 10_000
    assert res["rss_above_idle_mb"] < 1024
