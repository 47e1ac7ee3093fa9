"""`oricf bench NAME [...]`: runs the benchmark NAME's main(), and says in one line what a
benchmark needs that this installation lacks instead of a traceback.

A benchmark that needs a package beyond what `scripts/setup.sh` installs (the core
dependencies and the extras asr, llm, ros, audio) checks for it with `need()` before it
starts, or skips the part that needs it with `missing()`; any other import that fails is
caught here and named with the extra of oricf that declares it (from oricf's own metadata).
Tools and system packages (ffmpeg, GStreamer, iproute2) are named the same way.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import logging
import re
import shutil
from collections.abc import Callable

from oricf.errors import ConfigError

log = logging.getLogger(__name__)


class MissingPackage(ConfigError):
    """A benchmark needs a package or a tool that is not installed; the message says how
    to add it. A ConfigError, so `oricf` prints it as one line and exits 2."""


def install_hint(module: str, extra: str | None = None) -> str:
    """How to install the package that provides `module`: the extra of oricf that declares
    it (given, or found by name in oricf's metadata), else the package itself."""
    extra = extra or declaring_extra(module)
    return f"pip install 'oricf[{extra}]'" if extra else f"pip install {module}"


def declaring_extra(module: str) -> str | None:
    """The extra of the installed oricf whose requirement is named like `module`."""
    try:
        requirements = importlib.metadata.requires("oricf") or []
    except importlib.metadata.PackageNotFoundError:
        return None
    wanted = _normalized(module)
    for requirement in requirements:
        name = re.match(r"[A-Za-z0-9._-]+", requirement)
        extra = re.search(r"""extra\s*==\s*["']([^"']+)["']""", requirement)
        if name and extra and _normalized(name.group(0)) == wanted:
            return extra.group(1)
    return None


def _normalized(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def missing(module: str, extra: str | None = None) -> str | None:
    """None when `module` imports; else how to install it. Imported rather than looked up,
    so a package that is present but broken counts as missing too."""
    try:
        importlib.import_module(module)
    except ImportError:
        return install_hint(module, extra)
    return None


def need(module: str, extra: str, purpose: str) -> None:
    """Raises MissingPackage, naming `extra`, when `module` does not import."""
    hint = missing(module, extra)
    if hint is not None:
        raise MissingPackage(f"{purpose} needs {module}, which is not installed ({hint})")


def need_tools(tools: tuple[str, ...], packages: str, purpose: str) -> None:
    """Raises MissingPackage when a program in `tools` is not on PATH; `packages` says
    which system packages bring them."""
    absent = [tool for tool in tools if shutil.which(tool) is None]
    if absent:
        raise MissingPackage(f"{purpose} needs {', '.join(absent)}, not found on PATH "
                             f"({packages})")


def run(name: str, argv: list[str]) -> int:
    """oricf.bench.NAME's main(argv); a third-party module that fails to import, at the
    benchmark's import or while it runs, becomes one MissingPackage line."""
    try:
        main: Callable[[list[str]], int] = importlib.import_module(f"oricf.bench.{name}").main
        return main(argv)
    except ModuleNotFoundError as exc:
        top = (exc.name or "").split(".")[0]
        if not top or top == "oricf":
            raise  # a module of ORICF itself is missing: a broken installation, not an extra
        raise MissingPackage(f"oricf bench {name} needs {top}, which is not installed "
                             f"({install_hint(top)})") from None


def main(argv: list[str]) -> int:
    """`python -m oricf.bench.entry NAME [ARGS...]`, as `oricf bench` calls it."""
    return run(argv[0], argv[1:])
