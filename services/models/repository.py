"""Every declared model one server holds, loaded and closed together."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from oricf.errors import ConfigError, NotFound
from oricf.models.declaration import ModelDeclaration
from oricf.models.declared import DeclaredModel, FixedBatch
from oricf.models.info import ModelInfo
from oricf.models.tensors import clip
from oricf.store import ModelStore


class ModelRepository:
    def __init__(self, declarations: Iterable[ModelDeclaration], store: ModelStore,
                 batched: Mapping[str, FixedBatch] | None = None) -> None:
        """batched: the models the service batches requests to, and how their batches run."""
        batched = batched or {}
        self.models: dict[str, DeclaredModel] = {}
        for declaration in declarations:
            if declaration.name in self.models:
                raise ConfigError(f"models: two declarations name the model "
                                  f"'{declaration.name}'")
            self.models[declaration.name] = DeclaredModel(
                declaration, store, declaration.name in batched, batched.get(declaration.name))
        unknown = sorted(set(batched) - set(self.models))
        if unknown:
            raise ConfigError(f"batching: no model '{unknown[0]}' among models "
                              f"({', '.join(self.models)})")

    def get(self, name: str) -> DeclaredModel:
        try:
            return self.models[name]
        except KeyError:
            raise NotFound(f"no model '{clip(name)}' (this server has: "
                           f"{', '.join(self.models)})") from None

    def load(self) -> None:
        for model in self.models.values():
            model.load()

    def close(self) -> None:
        for model in self.models.values():
            model.close()

    def info(self) -> ModelInfo:
        infos = [model.info() for model in self.models.values()]
        return ModelInfo(model=", ".join(i.model for i in infos),
                         runtime=", ".join(sorted({i.runtime for i in infos})))
