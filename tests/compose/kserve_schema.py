"""The OpenAPI schemas of KServe's InferenceService and ServingRuntime, cut from KServe's CRDs
to what compose/kubernetes/kserve/ uses, for tests/compose/test_kubernetes.py.

    python -m tests.compose.kserve_schema KSERVE_CHECKOUT [--tag v0.20.0]

reads config/crd/full/serving.kserve.io_{inferenceservices,servingruntimes}.yaml of a KServe
checkout at that tag (`git show TAG:PATH`) and writes tests/compose/schemas/kserve.json:
each kind's openAPIV3Schema without descriptions, the InferenceService's without its status
and every spec part but the predictor, whose per-framework containers (sklearn, onnx,
triton...: the older form of `model`) and multi-node workerSpec are cut too. A cut part is
the schema `false`, so a manifest that starts using one fails until the file is made again
with that part kept.
"""

from __future__ import annotations

import argparse
import json
import subprocess
from pathlib import Path
from typing import Any

import yaml

OUT = Path(__file__).parent / "schemas" / "kserve.json"
CRDS = {
    "InferenceService": "config/crd/full/serving.kserve.io_inferenceservices.yaml",
    "ServingRuntime": "config/crd/full/serving.kserve.io_servingruntimes.yaml",
}
ISVC_SPEC_KEPT = {"predictor"}
PREDICTOR_CUT = {"sklearn", "xgboost", "tensorflow", "pytorch", "triton", "onnx", "pmml",
                 "lightgbm", "paddle", "huggingface", "workerSpec"}


def without_descriptions(node: Any) -> Any:
    if isinstance(node, dict):
        return {k: without_descriptions(v) for k, v in node.items() if k != "description"}
    if isinstance(node, list):
        return [without_descriptions(v) for v in node]
    return node


def cut(properties: dict[str, Any], names: set[str]) -> None:
    for name in names & properties.keys():
        properties[name] = False


def schema(checkout: Path, tag: str, kind: str) -> tuple[str, dict[str, Any]]:
    text = subprocess.run(["git", "-C", str(checkout), "show", f"{tag}:{CRDS[kind]}"],
                          check=True, capture_output=True, text=True).stdout
    crd = yaml.safe_load(text)
    (version,) = [v for v in crd["spec"]["versions"] if v.get("served") and v.get("storage")]
    api_version = f"{crd['spec']['group']}/{version['name']}"
    tree: dict[str, Any] = without_descriptions(version["schema"]["openAPIV3Schema"])
    tree["properties"].pop("status", None)
    if kind == "InferenceService":
        spec = tree["properties"]["spec"]["properties"]
        cut(spec, set(spec) - ISVC_SPEC_KEPT)
        cut(spec["predictor"]["properties"], PREDICTOR_CUT)
    return api_version, tree


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkout", type=Path, help="a clone of github.com/kserve/kserve")
    parser.add_argument("--tag", default="v0.20.0")
    args = parser.parse_args(argv)
    kinds = {}
    for kind in CRDS:
        api_version, tree = schema(args.checkout, args.tag, kind)
        kinds[kind] = {"apiVersion": api_version, "schema": tree}
    document = {"source": f"kserve/kserve {args.tag}: {', '.join(CRDS.values())} "
                          f"(Apache-2.0), cut by tests/compose/kserve_schema.py",
                "kinds": kinds}
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(document, separators=(",", ":"), sort_keys=True) + "\n")
    print(f"{OUT}: {OUT.stat().st_size:,} bytes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
