"""Makes the image's converted models during its build (compose/Dockerfile, models stage).

    python compose/convert_models.py MODEL ...     (catalog names: the MODELS build argument)

Every declaration under the config folder's models/ whose weights are one of the named
catalog entries with `convert:` (pybullet's policies: numpy arrays in a Python file) is
made into its model file beside the verified source now, as a service would at its first
load: in the image the store belongs to root and the services' user cannot write it, so
that first load would fail. ONNX files in such an entry's folder that the catalog does not
list (a store seeded from compose/.models holds the build machine's) are made again: what
the image holds comes from the verified source only.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import yaml

from oricf.config import config_dir
from oricf.errors import ConfigError, ModelMissing
from oricf.models.declaration import ModelDeclaration, load_declaration
from oricf.models.declared import DeclaredModel
from oricf.store import ModelStore

log = logging.getLogger("convert_models")


def to_convert(models: set[str], folder: Path) -> list[ModelDeclaration]:
    """The declarations under folder whose weights are a named catalog entry to convert."""
    found = []
    for path in sorted(folder.rglob("*.yaml")):
        raw = yaml.safe_load(path.read_text())
        weights = raw.get("weights") if isinstance(raw, dict) else None
        if isinstance(weights, dict) and weights.get("convert") \
                and weights.get("catalog") in models:
            found.append(load_declaration(path))
    return found


def convert(declaration: ModelDeclaration, store: ModelStore) -> Path:
    """The model file made from the declaration's verified weights, never an earlier one."""
    assert declaration.weights is not None and declaration.weights.catalog is not None
    name = declaration.weights.catalog
    listed = {f.name for f in store.entry(name).files}
    for stale in store.folder(name).glob("*.onnx"):
        if stale.name not in listed:
            stale.unlink()
    return DeclaredModel(declaration, store).weights_path()


def main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if not argv:
        print(__doc__, file=sys.stderr)
        return 2
    store = ModelStore()
    try:
        for declaration in to_convert(set(argv), config_dir() / "models"):
            made = convert(declaration, store)
            log.info("%s: %s", declaration.name, made)
    except (ConfigError, ModelMissing) as exc:
        log.error("%s", exc)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
