"""compose/kubernetes/ as kubectl would apply it: a copy of it and of configs/ in a temporary
folder, certificates made there by `oricf certs`, rendered by kustomize (kubectl kustomize or
the kustomize binary)."""

from __future__ import annotations

import base64
import shutil
import subprocess
from pathlib import Path
from typing import Any

import yaml

from oricf.config import REPO_ROOT
from oricf.launch.certs import make_certificates

KUBERNETES = REPO_ROOT / "compose" / "kubernetes"
KUSTOMIZATIONS = ("services", "kserve")
HOSTS = ["detector.oricf.svc.cluster.local", "localhost", "127.0.0.1"]
Document = dict[str, Any]


def kustomize() -> list[str] | None:
    """The command that renders a kustomization with files outside it, or None."""
    if shutil.which("kustomize"):
        return ["kustomize", "build", "--load-restrictor", "LoadRestrictionsNone"]
    if shutil.which("kubectl"):
        return ["kubectl", "kustomize", "--load-restrictor", "LoadRestrictionsNone"]
    return None


def workspace(root: Path) -> Path:
    """compose/kubernetes and configs/ copied under root (same layout), with certificates;
    returns root's compose/kubernetes."""
    copy = root / "compose" / "kubernetes"
    shutil.copytree(KUBERNETES, copy, ignore=shutil.ignore_patterns("certs"))
    shutil.copytree(REPO_ROOT / "configs", root / "configs")
    make_certificates(copy / "certs", HOSTS)
    return copy


def render(kubernetes: Path, name: str) -> list[Document]:
    """The objects a kustomization makes: by kustomize when there is one, else its own
    resource files plus its generators' objects under their plain names (no hash suffix)."""
    command = kustomize()
    if command is not None:
        result = subprocess.run([*command, str(kubernetes / name)], capture_output=True,
                                text=True, timeout=120)
        assert result.returncode == 0, f"kustomize {name}: {result.stderr}"
        return [d for d in yaml.safe_load_all(result.stdout) if d]
    return without_kustomize(kubernetes / name)


def without_kustomize(folder: Path) -> list[Document]:
    kustomization = yaml.safe_load((folder / "kustomization.yaml").read_text())
    documents: list[Document] = []
    for resource in kustomization.get("resources", []):
        path = folder / resource
        if path.is_dir():
            documents += without_kustomize(path)
        else:
            documents += [d for d in yaml.safe_load_all(path.read_text()) if d]
    for kind, key in (("ConfigMap", "configMapGenerator"), ("Secret", "secretGenerator")):
        for generator in kustomization.get(key, []):
            files = {}
            for entry in generator["files"]:
                name, _, path = entry.rpartition("=") if "=" in entry else ("", "", entry)
                files[name or Path(path).name] = (folder / path).read_text()
            if kind == "Secret":  # base64, as kustomize writes it
                files = {k: base64.b64encode(v.encode()).decode() for k, v in files.items()}
            documents.append({"apiVersion": "v1", "kind": kind, "data": files,
                              "metadata": {"name": generator["name"]}})
    return documents


def file_contents(document: Document) -> dict[str, str]:
    """A ConfigMap's or Secret's files by key, decoded."""
    if document["kind"] == "ConfigMap":
        return dict(document["data"])
    return {k: base64.b64decode(v).decode() for k, v in document["data"].items()}


def by_kind(documents: list[Document], kind: str) -> dict[str, Document]:
    return {d["metadata"]["name"]: d for d in documents if d["kind"] == kind}
