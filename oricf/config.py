"""One loader for every YAML file ORICF reads.

Each file has a pydantic schema that refuses unknown keys. Errors name the file and the
path of the bad key (``configs/x.yaml: routes[2].timeout_ms: must be > 0``). Relative paths
in a file resolve against the folder of that file, an overlay's included: each string an
overlay brings carries its folder until the schema has read it.
"""

from __future__ import annotations

import importlib.resources
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Annotated, Any, TypeVar

from pydantic import BaseModel, BeforeValidator, ConfigDict, ValidationError, ValidationInfo

from oricf.errors import ConfigError
from oricf.yamlfile import parse_yaml, read_yaml

# The checkout's root when ORICF runs from one (an editable install); meaningless in an
# installed wheel, where configs/ ships inside the package instead (see config_dir()).
REPO_ROOT = Path(__file__).resolve().parent.parent


class Schema(BaseModel):
    """Base of every config schema: unknown keys are errors, values are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class FromFile(str):
    """A string read from an overlay file, with that file's folder: a relative path in an
    overlay means what it means beside the overlay, not beside the file it overlays."""

    folder: Path

    def __new__(cls, value: str, folder: Path) -> FromFile:
        text = super().__new__(cls, value)
        text.folder = folder
        return text


def _with_folder(data: Any, folder: Path) -> Any:
    if isinstance(data, str):
        return FromFile(data, folder)
    if isinstance(data, Mapping):
        return {key: _with_folder(value, folder) for key, value in data.items()}
    if isinstance(data, list):
        return [_with_folder(value, folder) for value in data]
    return data


def resolve_path(value: Any, info: ValidationInfo) -> Any:
    """A relative path against the folder of the file that said it (the overlay's for a
    string an overlay brought, else the validated file's); anything but a path is left to
    the schema to refuse."""
    if not isinstance(value, str | Path):
        return value
    base = getattr(value, "folder", None) or (info.context or {}).get("base_dir")
    path = Path(os.path.expanduser(str(value)))
    if base is not None and not path.is_absolute():
        path = Path(base) / path
    return path


# A path in a YAML file: relative paths resolve against the folder of the file.
FilePath = Annotated[Path, BeforeValidator(resolve_path)]

T = TypeVar("T", bound=BaseModel)


def config_dir() -> Path:
    """Where the default configs live: $ORICF_CONFIG_DIR; else, running from a checkout, its
    configs/; else the copy a wheel installs inside the package (oricf/configs). Raises
    ConfigError naming what it looked for when none of them is a folder."""
    chosen = os.environ.get("ORICF_CONFIG_DIR")
    if chosen:
        path = Path(chosen).expanduser()
        if not path.is_dir():
            raise ConfigError(f"ORICF_CONFIG_DIR={chosen}: no such folder")
        return path
    checkout = REPO_ROOT / "configs"
    if (REPO_ROOT / "pyproject.toml").is_file() and checkout.is_dir():
        return checkout
    installed = installed_config_dir()
    if installed is not None:
        return installed
    package = importlib.resources.files("oricf").joinpath("configs")
    raise ConfigError(f"no configs folder: {package} is missing and {REPO_ROOT} is not a "
                      f"checkout; reinstall ORICF (a wheel ships configs/ as oricf/configs) "
                      f"or set ORICF_CONFIG_DIR")


def installed_config_dir() -> Path | None:
    """oricf/configs as a wheel installs it (pyproject.toml maps the repository's configs/
    onto the package `oricf.configs`), if it is a real folder: YAML files name each other by
    relative paths, so a copy inside a zip archive would not do."""
    folder = importlib.resources.files("oricf").joinpath("configs")
    return folder if isinstance(folder, Path) and folder.is_dir() else None


def shipped_service_config(service: str) -> Path:
    """A service's default YAML (`oricf serve SERVICE` without --config)."""
    return config_dir() / "services" / f"{service}.yaml"


def format_location(loc: Iterable[Any]) -> str:
    text = ""
    for part in loc:
        if isinstance(part, int):
            text += f"[{part}]"
        else:
            text += f".{part}" if text else str(part)
    return text or "(top level)"


def deep_merge(base: Any, overlay: Any) -> Any:
    """Overlay wins; mappings merge key by key, everything else is replaced."""
    if isinstance(base, Mapping) and isinstance(overlay, Mapping):
        merged = dict(base)
        for key, value in overlay.items():
            merged[key] = deep_merge(base.get(key), value) if key in base else value
        return merged
    return overlay


def apply_set(data: Any, assignment: str) -> Any:
    """`KEY.PATH=VALUE` (a command line's --set) applied to parsed YAML; VALUE is read as YAML
    (`3`, `true`, `[a, b]`, `{x: 1}`), except that only `[...]` and `{...}` make a list or a
    mapping (so `-` stays a string); a number indexes into an existing list. Returns a copy;
    the caller validates the result like the file."""
    path, sep, text = assignment.partition("=")
    keys = path.strip().split(".")
    if not sep or not all(keys):
        raise ConfigError(f"--set {assignment}: expected KEY.PATH=VALUE")
    value = parse_yaml(text, f"--set {path}: the value") if text.strip() else ""
    if isinstance(value, list | dict) and not text.strip().startswith(("[", "{")):
        value = text
    return _set(data, keys, value, path)


def _set(node: Any, keys: list[str], value: Any, path: str) -> Any:
    if not keys:
        return value
    key, rest = keys[0], keys[1:]
    if isinstance(node, list):
        if not key.isdigit() or int(key) >= len(node):
            raise ConfigError(f"--set {path}: '{key}' is not an index of a list of "
                              f"{len(node)} items")
        copy = list(node)
        copy[int(key)] = _set(node[int(key)], rest, value, path)
        return copy
    if node is None:
        node = {}
    if not isinstance(node, Mapping):
        raise ConfigError(f"--set {path}: '{key}' is under a value that is not a mapping")
    merged = dict(node)
    merged[key] = _set(node.get(key), rest, value, path)
    return merged


def validate(data: Any, schema: type[T], source: str, base_dir: Path | None = None) -> T:
    """Validates already-parsed data; errors are ConfigError naming source and key."""
    if data is None:
        data = {}
    try:
        return schema.model_validate(data, context={"base_dir": base_dir})
    except ValidationError as exc:
        lines = [f"{source}: {format_location(_location(e))}: {_message(e)}"
                 for e in exc.errors()]
        raise ConfigError("\n".join(lines)) from None


def _location(error: Mapping[str, Any]) -> tuple[Any, ...]:
    """Where the error is; a discriminated union's own errors point at its tag key."""
    loc = tuple(error["loc"])
    if error["type"] in ("union_tag_invalid", "union_tag_not_found"):
        return (*loc, str(error["ctx"]["discriminator"]).strip("'"))
    return loc


def _message(error: Mapping[str, Any]) -> str:
    if error["type"] == "extra_forbidden":
        return "unknown key"
    if error["type"] == "union_tag_invalid":
        return (f"'{error['ctx']['tag']}' is not one of "
                f"{str(error['ctx']['expected_tags']).replace(chr(39), '')}")
    if error["type"] == "union_tag_not_found":
        return "required"
    message = str(error["msg"])
    return message.removeprefix("Value error, ")


def read_with_overlays(path: Path, overlays: Iterable[Path | str] = (),
                       sets: Iterable[str] = ()) -> tuple[Any, list[str]]:
    """A YAML file with overlay files merged on top in order, then `KEY=VALUE` assignments
    (apply_set), and the names of all of them."""
    data = read_yaml(path)
    sources = [str(path)]
    for overlay in overlays:
        overlay = Path(overlay)
        data = deep_merge(data, _with_folder(read_yaml(overlay), overlay.parent))
        sources.append(str(overlay))
    sets = list(sets)
    for assignment in sets:
        data = apply_set(data, assignment)
    if sets:
        sources.append("--set")
    return data, sources


def load_config(path: Path | str, schema: type[T], overlays: Iterable[Path | str] = ()) -> T:
    """Reads a YAML file (plus overlay files merged on top) and validates it against schema."""
    path = Path(path)
    data, sources = read_with_overlays(path, overlays)
    return validate(data, schema, " + ".join(sources), base_dir=path.parent)
