"""`oricf bench soak`: a short run of the real voice demo pipeline (the services, the gateway
speaking, the live view with a viewer, vtest.avi, espeak-ng questions) reports every process
and every question; and what the report makes of samples, log lines and answers. Checks that
everything is measured, never how much (benchmarks are commands, not timed assertions)."""

from __future__ import annotations

import csv
import json
import os
from collections import Counter
from pathlib import Path

import pytest

from oricf.bench.soak import parse_args, report
from oricf.bench.soak_report import (
    Answer,
    LogErrors,
    Outcome,
    Sample,
    growth_mb_per_h,
    print_summary,
    read_process,
    stated_numbers,
    summarize,
)
from tests.launch.helpers import (
    OricfCommand,
    private_ros_env,
    service_entry,
    shipped_pipeline,
    write_deployment,
)
from tests.support.processes import free_port

PROCESSES = {"detector", "asr", "llm", "tts", "gateway", "viewer", "bench"}


@pytest.mark.bench
def test_a_short_soak_reports_every_process_and_every_question(tmp_path: Path) -> None:
    deployment = write_deployment(tmp_path, {
        "services": {name: service_entry(free_port()) for name in ("detector", "asr", "llm")},
        "gateway": {"config": shipped_pipeline()}})
    report_file = tmp_path / "soak.json"
    command = OricfCommand("bench", "soak", "--deployment", str(deployment), "--minutes", "0.5",
                           "--every", "10", "--sample-every", "10", "--warmup", "0",
                           "--report", str(report_file), "--log", str(tmp_path / "soak.log"),
                           env=private_ros_env())
    try:
        assert command.finish(timeout=600) == 0, command.output
    finally:
        command.kill()
    found = json.loads(report_file.read_text())
    processes = {p["process"]: p for p in found["processes"]}
    assert set(processes) == PROCESSES, found["processes"]
    for row in processes.values():
        assert row["rss_first_mb"] > 0 and row["rss_last_mb"] > 0 and not row["ended"], row
        assert row["growth_mb_per_h"] is not None and row["error_lines"] == 0, row
    questions = found["questions"]
    assert questions["asked"] >= 2 and questions["answered"] == questions["asked"], found
    assert f"answered {questions['answered']}/{questions['asked']} questions" in command.output
    assert all(a["first_audio_ms"] is not None for a in found["answers"]), found["answers"]
    assert found["viewer_images_per_s"] > 0  # the viewer watched the camera throughout
    with report_file.with_suffix(".csv").open() as handle:
        rounds = Counter(row["process"] for row in csv.DictReader(handle))
    assert set(rounds) == PROCESSES and min(rounds.values()) >= 3, rounds


def answer(text: str | None, count: int = 4) -> Answer:
    return Answer(1.0, "How many people do you see?", "How many people do you see?", count,
                  text, 500.0, 900.0)


def outcome_of(*answers: Answer) -> Outcome:
    samples = [Sample(t, "gateway", 1, 200.0 + t / 60, t / 10) for t in (0.0, 60.0, 120.0)]
    return Outcome(list(answers), samples, 5.0)


def log_with(tmp_path: Path, *lines: str) -> LogErrors:
    path = tmp_path / "processes.log"
    path.write_text("".join(f"{line}\n" for line in lines))
    errors = LogErrors(path)
    errors.scan()
    return errors


def test_an_error_line_in_a_process_log_fails_the_soak(tmp_path: Path) -> None:
    errors = log_with(tmp_path, "gateway  | 12:00:01 INFO  oricf.gateway: started",
                      "llm      | 12:00:02 ERROR oricf.services: the model failed",
                      "gateway  | Traceback (most recent call last):")
    assert errors.counts == {"llm": 1, "gateway": 1}
    args = parse_args(["--warmup", "0"])
    assert report(outcome_of(answer("I see 4 people.")), errors, args) == 1


def test_an_unanswered_question_fails_the_soak_and_a_wrong_answer_is_counted(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = parse_args(["--warmup", "0"])
    clean = log_with(tmp_path, "gateway  | 12:00:01 INFO  oricf.gateway: started")
    assert report(outcome_of(answer("I see 4 people."), answer("I see five people.")),
                  clean, args) == 0
    assert "answered 2/2 questions; 1 answers did not state the count" in capsys.readouterr().out
    assert report(outcome_of(answer("I see 4 people."), answer(None)), clean, args) == 1


def test_a_log_line_still_being_written_is_read_once_it_is_whole(tmp_path: Path) -> None:
    path = tmp_path / "processes.log"
    path.write_text("llm      | 12:00:02 ERR")
    errors = LogErrors(path)
    errors.scan()
    with path.open("a") as handle:
        handle.write("OR oricf.services: the model failed\n")
    errors.scan()
    errors.scan()
    assert errors.counts == {"llm": 1}


def test_growth_is_the_slope_after_the_warm_up_per_hour() -> None:
    # 300 MB while warming up, then 1 MB more a minute: 60 MB an hour.
    samples = [Sample(0.0, "llm", 1, 300.0, 0.0)] + [
        Sample(60.0 * k, "llm", 1, 400.0 + k, 0.0) for k in range(1, 11)]
    assert growth_mb_per_h(samples, warmup_s=60) == pytest.approx(60.0)
    assert growth_mb_per_h(samples[:2], warmup_s=60) is None
    summary, = summarize(samples, 60, Counter())
    assert (summary.rss_first_mb, summary.rss_last_mb) == (300.0, 410.0)
    assert summary.late_from_s == pytest.approx(420.0)  # the last third after the warm-up
    assert summary.late_growth_mb_per_h == pytest.approx(60.0)  # a leak keeps its slope
    assert summary.still_growing == ["rss"]  # no anonymous/file split read: RSS itself


def by_minute(anon: list[float], file: list[float]) -> list[Sample]:
    """A sample a minute of a process whose RSS is its anonymous and file-backed memory."""
    return [Sample(60.0 * k, "llm", 1, a + f, 0.0, a, f)
            for k, (a, f) in enumerate(zip(anon, file, strict=True))]


def test_memory_that_rose_and_then_sat_flat_is_not_reported_as_growing(
        capsys: pytest.CaptureFixture[str]) -> None:
    # Ten minutes: 431 MB rising to 548 MB by minute 7 (a model's pages and buffers filling),
    # then flat give or take half a megabyte. A line over the second half still climbs
    # (+518 MB/h in such a run); over the last third it is flat.
    anon = [120.0, 135, 150, 165, 180, 195, 205, 212, 211.5, 212, 211.6]
    file = [311.0, 320, 328, 333, 335, 336, 336, 336, 336, 336.5, 336]
    summary, = summarize(by_minute(anon, file), 60, Counter())
    assert summary.growth_mb_per_h is not None and summary.growth_mb_per_h > 300
    assert summary.late_growth_mb_per_h == pytest.approx(0.0, abs=20)
    assert summary.still_growing == []
    assert (summary.anon_first_mb, summary.anon_last_mb) == (120.0, 211.6)
    assert (summary.file_first_mb, summary.file_last_mb) == (311.0, 336.0)
    print_summary([summary], [], 60)
    out = capsys.readouterr().out
    assert "flat" in out and "still growing in the last third: none" in out


def test_memory_that_keeps_rising_is_reported_with_the_memory_that_grows(
        capsys: pytest.CaptureFixture[str]) -> None:
    # The anonymous memory climbs 2 MB a minute to the end; the mapped file levels off.
    anon = [120.0 + 2 * k for k in range(11)]
    file = [311.0, 330, 336, 336, 336, 336, 336, 336, 336, 336, 336]
    summary, = summarize(by_minute(anon, file), 60, Counter())
    assert summary.still_growing == ["anon"]
    assert summary.late_anon_mb_per_h == pytest.approx(120.0)
    assert summary.late_file_mb_per_h == pytest.approx(0.0)
    print_summary([summary], [], 60)
    out = capsys.readouterr().out
    assert "GROWING anon" in out and "still growing in the last third: llm (anon)" in out


def test_memory_that_moves_up_and_down_is_flat_within_its_noise() -> None:
    # A speech voice's buffers: runs of different lengths move RSS by 20 MB either way.
    anon = [200.0, 240, 215, 238, 210, 236, 212, 239, 214, 237, 216]
    summary, = summarize(by_minute(anon, [90.0] * 11), 60, Counter())
    assert summary.still_growing == []


def test_the_soak_reads_anonymous_and_file_backed_memory_of_a_process() -> None:
    sample = read_process("bench", os.getpid(), 1.0)
    assert sample.anon_mb is not None and sample.file_mb is not None
    assert sample.rss_mb is not None and sample.anon_mb + sample.file_mb <= sample.rss_mb + 1
    assert sample.anon_mb > 0 and sample.file_mb > 0  # a heap, and python's own mapped files


def test_a_process_that_ended_is_reported_and_fails_the_soak(tmp_path: Path) -> None:
    outcome = outcome_of(answer("I see 4 people."))
    outcome.samples.append(Sample(180.0, "gateway", 1, None, None))
    summary, = summarize(outcome.samples, 0, Counter())
    assert summary.ended and summary.rss_last_mb == pytest.approx(202.0)
    assert report(outcome, log_with(tmp_path), parse_args([])) == 1


@pytest.mark.parametrize(("text", "numbers"), [
    ("I see 4 people.", {4}), ("There are twelve people.", {12}), ("I see no one.", {0}),
    ("Yes, I see 3 people and 1 dog.", {3, 1}), ("I cannot tell.", set())])
def test_the_numbers_an_answer_states(text: str, numbers: set[int]) -> None:
    assert stated_numbers(text) == numbers
