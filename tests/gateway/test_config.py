"""Pipeline YAML: the shipped files load; every mistake names the file and the key."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from oricf.config import config_dir
from oricf.errors import ConfigError
from oricf.gateway.config import load_pipeline
from oricf.gateway.shells.main import main

PIPELINES = config_dir() / "pipelines"
PEOPLE_QA = PIPELINES / "people_qa.yaml"

MINIMAL: dict[str, Any] = {
    "endpoints": {"detector": {"address": "127.0.0.1:50051"}},
    "routes": {"people": {
        "input": {"topic": "camera/image_raw", "type": "sensor_msgs/Image"},
        "call": {"service": "detector", "method": "Detect", "labels": ["person"]},
        "post": [{"count": {"label": "person"}}],
        "outputs": [{"topic": "/human_counter", "type": "std_msgs/Int32", "from": "count"}],
    }},
}


def write(tmp_path: Path, data: Any, name: str = "pipeline.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def edited(change: dict[str, Any]) -> dict[str, Any]:
    from oricf.config import deep_merge

    return deep_merge(MINIMAL, change)  # type: ignore[no-any-return]


def test_reference_pipeline_keeps_the_fixed_topic_names() -> None:
    config = load_pipeline(PEOPLE_QA)
    people, speech = config.routes["people"], config.routes["speech"]
    assert (people.input.topic, people.input.type) == ("camera/image_raw", "sensor_msgs/Image")
    assert {(o.topic, o.type) for o in people.outputs if o.topic} == {
        ("/human_counter", "std_msgs/Int32"), ("/camera/image_annotated", "sensor_msgs/Image")}
    assert [o.product for o in people.outputs if o.product] == ["people_count"]
    assert speech.input.topic == "/audio/utterance"
    assert [o.topic for o in speech.outputs if o.topic] == ["/speech/transcript"]
    assert config.routes["typed_question"].input.topic == "/question"
    for name in ("typed_question", "spoken_question"):
        route = config.routes[name]
        assert route.call.context is not None
        assert route.call.context.products == ["people_count"]
        assert [o.topic for o in route.outputs] == ["/answer"]
    assert {n: e.address for n, e in config.endpoints.items()} == {
        "detector": "127.0.0.1:50051", "asr": "127.0.0.1:50052", "llm": "127.0.0.1:50053"}


@pytest.mark.parametrize("placement", ["onboard", "edge", "ollama"])
def test_placement_overlays_change_endpoints_only(placement: str) -> None:
    placed = load_pipeline(PEOPLE_QA, [PIPELINES / "placement" / f"{placement}.yaml"])
    assert placed.routes == load_pipeline(PEOPLE_QA).routes
    detector = placed.endpoints["detector"]
    if placement == "edge":
        assert detector.address == "edge.local:50051"
        assert detector.fallback == "127.0.0.1:50051"
        assert detector.image.transport == "jpeg"
        assert detector.deadline_ms == 800
    else:
        assert detector.address == "127.0.0.1:50051" and detector.image.transport == "raw"
    if placement == "ollama":
        llm = placed.endpoints["llm"].targets
        assert (llm["address"].protocol, llm["fallback"].protocol) == ("openai", "grpc")


def test_profile_option_is_gone(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["--config", str(PEOPLE_QA), "--profile", "edge", "--check"])
    assert exit_.value.code == 2
    assert "unrecognized arguments: --profile edge" in capsys.readouterr().err


BAD = [
    # A call's keys are its method's: the path names the method whose schema refused them.
    ({"routes": {"people": {"call": {"deadline": 3}}}},
     "routes.people.call.Detect.deadline: unknown key"),
    ({"endpoints": {"detector": {"address": "localhost"}}},
     "endpoints.detector.address: 'localhost' is not host:port"),
    ({"endpoints": {"detector": {"deadline_ms": 0}}}, "endpoints.detector.deadline_ms"),
    ({"endpoints": {"detector": {"token_header": "triton-grpc-protocol-triton-access-token"}}},
     "endpoints.detector: token_header: given without a token"),
    ({"endpoints": {"detector": {"token": {"env": "T"}, "token_header": "key-bin"}}},
     "endpoints.detector: token_header: key-bin: reserved (gRPC keeps grpc-* keys and *-bin "
     "ones carry bytes"),
    *[({"endpoints": {"detector": {"token": {"env": "T"}, "token_header": key}}},
       f"endpoints.detector: token_header: {key}: reserved")
      for key in ("content-type", "te", "user-agent", "host", "connection",
                  "transfer-encoding", "traceparent", "tracestate", "baggage",
                  "grpc-timeout", "x-b3-traceid")],
    ({"endpoints": {"detector": {"token": {"env": "T"}, "token_header": "authorization"}}},
     "endpoints.detector: token_header: authorization is where the token goes without"),
    ({"endpoints": {"detector": {"token": {"env": "T"}, "token_header": ":path"}}},
     "endpoints.detector.token_header: String should match pattern"),
    ({"endpoints": {"detector": {"token": {"env": "T"}, "token_header": "Bearer x"}}},
     "endpoints.detector.token_header: String should match pattern"),
    ({"endpoints": {"detector": {"image": {"transport": "png"}}}},
     "endpoints.detector.image.transport"),
    ({"executor": "fast"}, "executor: Input should be 'python' or 'events'"),
    ({"executor": "events", "executor_threads": 4},
     "executor_threads: 4, but the events executor runs on one thread"),
    ({"routes": {"people": {"call": {"service": "detektor"}}}},
     "routes.people.call.service: no endpoint 'detektor'"),
    ({"routes": {"people": {"call": {"method": "Classify"}}}}, "routes.people.call.method"),
    ({"routes": {"people": {"call": {"max_tokens": 5}}}},
     "routes.people.call.Detect.max_tokens: unknown key"),
    ({"routes": {"people": {"input": {"type": "sensor_msgs/PointCloud2"}}}},
     "routes.people.input.type"),
    ({"routes": {"people": {"input": {"product": "frames"}}}},
     "give exactly one of topic, product, url, audio, text"),
    ({"routes": {"people": {"input": {"keep": "queue"}}}},
     "routes.people.input: keep: camera inputs keep only the newest frame"),
    ({"routes": {"people": {"post": [{"count": {}, "annotate": {}}]}}},
     "routes.people.post[0]: give exactly one of"),
    ({"routes": {"people": {"outputs": [{"topic": "/n", "type": "std_msgs/Int32",
                                         "from": "cnt"}]}}},
     "routes.people.outputs[0].from: no field 'cnt'"),
    ({"routes": {"people": {"outputs": [{"topic": "/n", "from": "count"}]}}},
     "type: required with topic"),
    ({"routes": {"more": {"input": {"topic": "cam2", "type": "sensor_msgs/Image"},
                          "call": {"service": "detector", "method": "Detect"},
                          "outputs": [{"topic": "/human_counter", "type": "std_msgs/String",
                                       "from": "detections"}]}}},
     "outputs[0].type: /human_counter is already std_msgs/"),
    ({"routes": {"ask": {"input": {"topic": "/q", "type": "std_msgs/String"},
                         "call": {"service": "detector", "method": "Generate"},
                         "outputs": [{"topic": "/a", "type": "std_msgs/String",
                                      "from": "answer"}]}}},
     "call.service: endpoint 'detector' would serve both"),
    # A text input or output names a channel of `channels:`, or '-' (standard in/out).
    ({"endpoints": {"llm": {"address": "127.0.0.1:50053"}},
      "routes": {"ask": {"input": {"text": "typed"},
                         "call": {"service": "llm", "method": "Generate"},
                         "outputs": [{"text": "-", "from": "answer"}]}}},
     "routes.ask.input.text: no channel 'typed' (channels: none; or '-')"),
    ({"routes": {"people": {"outputs": [{"text": "spoken", "from": "count"}]}}},
     "routes.people.outputs[0].text: no channel 'spoken' (channels: none; or '-')"),
    # A camera topic's frames come with their header; a video's do not.
    ({"routes": {"people": {"input": {"topic": None, "type": None,
                                      "url": "people.mp4"},
                            "outputs": [{"jsonl": "-", "from": "header"}]}}},
     "routes.people.outputs[0].from: no field 'header' in this route"),
]


@pytest.mark.parametrize(("change", "message"), BAD)
def test_mistakes_name_the_file_and_the_key(tmp_path: Path, change: dict[str, Any],
                                            message: str) -> None:
    path = write(tmp_path, edited(change))
    with pytest.raises(ConfigError) as error:
        load_pipeline(path)
    assert str(path) in str(error.value)
    assert message in str(error.value)


def test_a_camera_topic_route_has_the_header_and_uses_ros(tmp_path: Path) -> None:
    header = {"routes": {"people": {"outputs": [{"jsonl": "-", "from": "header"}]}}}
    assert load_pipeline(write(tmp_path, edited(header))).uses_ros
    assert load_pipeline(write(tmp_path, MINIMAL)).uses_ros


@pytest.mark.parametrize(("change", "ros"), [
    ({"input": {"topic": None, "type": None, "url": "people.mp4"}}, True),  # topic output
    ({"outputs": [{"jsonl": "-", "from": "count"}]}, True),                 # topic input
    ({"input": {"topic": None, "type": None, "url": "people.mp4"},
      "outputs": [{"jsonl": "-", "from": "count"}]}, False),
])
def test_the_gateway_needs_ros_for_a_topic_input_or_output(tmp_path: Path,
                                                           change: dict[str, Any],
                                                           ros: bool) -> None:
    config = load_pipeline(write(tmp_path, edited({"routes": {"people": change}})))
    assert config.uses_ros is ros


def test_context_must_name_a_product_some_route_outputs(tmp_path: Path) -> None:
    data = edited({"endpoints": {"llm": {"address": "127.0.0.1:50053"}},
                   "routes": {"ask": {
                       "input": {"topic": "/q", "type": "std_msgs/String"},
                       "call": {"service": "llm", "method": "Generate",
                                "context": {"products": ["people_count"]}},
                       "outputs": [{"topic": "/a", "type": "std_msgs/String",
                                    "from": "answer"}]}}})
    message = r"routes.ask.call.context.products\[0\]: no route outputs 'people_count'"
    with pytest.raises(ConfigError, match=message):
        load_pipeline(write(tmp_path, data))


def test_overlay_errors_name_every_file(tmp_path: Path) -> None:
    base = write(tmp_path, MINIMAL)
    overlay = write(tmp_path, {"endpoints": {"detector": {"fallback": "nowhere"}}}, "edge.yaml")
    with pytest.raises(ConfigError) as error:
        load_pipeline(base, [overlay])
    assert f"{base} + {overlay}: endpoints.detector.fallback: 'nowhere'" in str(error.value)


def test_check_option_validates_without_ros(capsys: pytest.CaptureFixture[str],
                                            tmp_path: Path) -> None:
    edge = PIPELINES / "placement" / "edge.yaml"
    assert main(["--config", str(PEOPLE_QA), "--overlay", str(edge), "--check"]) == 0
    assert "4 routes" in capsys.readouterr().out
    with pytest.raises(ConfigError, match="file not found"):
        main(["--config", str(tmp_path / "missing.yaml"), "--check"])


def test_check_reads_every_token_naming_the_file_and_the_key(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A token the schema takes but that cannot be used stops --check (and so the start),
    naming the pipeline's files and the key: not the first call, with INTERNAL."""
    empty = tmp_path / "empty.tokens"
    empty.write_text("\n")
    empty.chmod(0o600)
    monkeypatch.delenv("ORICF_TEST_UNSET", raising=False)
    cases = {"endpoints.detector.token.file=" + str(tmp_path / "missing"):
             f"endpoints.detector.token.file: {tmp_path / 'missing'}: file not found",
             f"endpoints.llm.token.file={empty}":
             f"endpoints.llm.token.file: {empty}: no token",
             "endpoints.asr.token.env=ORICF_TEST_UNSET":
             "endpoints.asr.token.env: $ORICF_TEST_UNSET: not set",
             f"control.approvers.file={empty}": f"control.approvers.file: {empty}: no token"}
    control = f"control.listen=unix:{tmp_path / 'control.sock'}"
    for assignment, reason in cases.items():
        with pytest.raises(ConfigError) as error:
            main(["--config", str(PEOPLE_QA), "--set", control, "--set", assignment, "--check"])
        assert str(error.value).startswith(f"{PEOPLE_QA} + --set: {reason}")
