"""Regenerates the Python stubs from protos/: `.venv/bin/python scripts/protogen.py`.

The stubs are committed next to the .proto files so that installing ORICF needs no
code generator; tests/test_protos.py fails when they are stale. Never edit them by hand.
This works in a checkout only (it reads protos/ beside scripts/); it needs grpcio-tools,
which the dev extra installs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

PROTO_ROOT = Path(__file__).resolve().parent.parent / "protos"


def proto_files(root: Path = PROTO_ROOT) -> list[Path]:
    """Every .proto under root; none is an error."""
    files = sorted((root / "oricf").rglob("*.proto"))
    if not files:
        raise FileNotFoundError(f"no .proto files under {root / 'oricf'}")
    return files


def generate(out_dir: Path, root: Path = PROTO_ROOT) -> None:
    """Writes *_pb2.py, *_pb2.pyi and *_pb2_grpc.py for every proto into out_dir."""
    import grpc_tools
    from grpc_tools import protoc

    well_known = Path(grpc_tools.__file__).parent / "_proto"
    args = [
        "grpc_tools.protoc",
        f"-I{root}",
        f"-I{well_known}",
        f"--python_out={out_dir}",
        f"--pyi_out={out_dir}",
        f"--grpc_python_out={out_dir}",
        *(str(p.relative_to(root)) for p in proto_files(root)),
    ]
    if protoc.main(args) != 0:
        raise RuntimeError("protoc failed; see the messages above")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=PROTO_ROOT,
                        help="output root (default: protos/)")
    args = parser.parse_args(argv)
    generate(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
