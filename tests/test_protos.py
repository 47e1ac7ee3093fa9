"""The committed stubs are exactly what `python -m oricf.protogen` generates."""

from pathlib import Path

from oricf.protogen import PROTO_ROOT, generate


def test_generated_stubs_are_up_to_date(tmp_path: Path) -> None:
    generate(tmp_path)
    fresh = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*_pb2*.py*"))
    assert fresh, "protoc generated nothing"
    committed = sorted(p.relative_to(PROTO_ROOT) for p in PROTO_ROOT.rglob("*_pb2*.py*"))
    assert committed == fresh, "stub files differ: run `python -m oricf.protogen`"
    stale = [str(p) for p in fresh if (tmp_path / p).read_bytes() != (PROTO_ROOT / p).read_bytes()]
    assert not stale, f"stale generated code (run `python -m oricf.protogen`): {stale}"


def test_stubs_import_through_the_project_namespace() -> None:
    from oricf.v1 import detector_pb2, language_pb2, speech_pb2

    services = {
        s.full_name
        for module in (detector_pb2, speech_pb2, language_pb2)
        for s in module.DESCRIPTOR.services_by_name.values()
    }
    assert services == {"oricf.v1.Detector", "oricf.v1.SpeechRecognizer", "oricf.v1.LanguageModel"}
