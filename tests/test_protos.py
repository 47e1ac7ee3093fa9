"""The committed stubs are exactly what `python scripts/protogen.py` generates."""

from pathlib import Path

import pytest

from tests.support.scripts import load_script

protogen = load_script("protogen")
PROTO_ROOT, generate = protogen.PROTO_ROOT, protogen.generate


def test_generated_stubs_are_up_to_date(tmp_path: Path) -> None:
    generate(tmp_path)
    fresh = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*_pb2*.py*"))
    assert fresh, "protoc generated nothing"
    committed = sorted(p.relative_to(PROTO_ROOT) for p in PROTO_ROOT.rglob("*_pb2*.py*")
                       if "__pycache__" not in p.parts)
    assert committed == fresh, "stub files differ: run `python scripts/protogen.py`"
    stale = [str(p) for p in fresh if (tmp_path / p).read_bytes() != (PROTO_ROOT / p).read_bytes()]
    assert not stale, f"stale generated code (run `python scripts/protogen.py`): {stale}"


def test_stubs_import_through_the_project_namespace() -> None:
    from oricf.v1 import detector_pb2, language_pb2, speech_pb2, synthesis_pb2

    services = {
        s.full_name
        for module in (detector_pb2, speech_pb2, language_pb2, synthesis_pb2)
        for s in module.DESCRIPTOR.services_by_name.values()
    }
    assert services == {"oricf.v1.Detector", "oricf.v1.SpeechRecognizer", "oricf.v1.LanguageModel",
                        "oricf.v1.SpeechSynthesizer"}


def test_this_environment_runs_protobuf_6() -> None:
    """The test set-up installs tritonclient and kserve, which hold protobuf below 7."""
    import google.protobuf

    assert google.protobuf.__version__.startswith("6.")


@pytest.mark.long
def test_stubs_run_on_protobuf_7_too(tmp_path: Path) -> None:
    """The stubs are generated for protobuf 6 (so ORICF installs beside tritonclient, kserve
    or mlserver, which need protobuf < 7); they must import on protobuf 7 as well."""
    import subprocess
    import sys

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = str(venv / "bin" / "python")
    subprocess.run([python, "-m", "pip", "install", "-q", "--disable-pip-version-check",
                    "protobuf>=7,<8", "grpcio>=1.81.1"], check=True, timeout=600)
    package = tmp_path / "path" / "oricf"  # the stubs under their own namespace, nothing else
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    for folder in ("v1", "oip"):
        (package / folder).symlink_to(PROTO_ROOT / "oricf" / folder)
    script = ("import google.protobuf as p; assert p.__version__.startswith('7.'), p.__version__\n"
              "from oricf.v1 import detector_pb2_grpc, language_pb2_grpc, speech_pb2_grpc\n"
              "from oricf.v1 import synthesis_pb2_grpc\n"
              "from oricf.oip import open_inference_grpc_pb2_grpc\n"
              "print('ok', p.__version__)\n")
    result = subprocess.run([python, "-c", script], capture_output=True, text=True,
                            env={"PYTHONPATH": str(tmp_path / "path"),
                                 "PYTHONDONTWRITEBYTECODE": "1"}, cwd=tmp_path, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("ok 7.")
