"""compose/smoke_check.py as a module: the requests and answer checks of the compose smoke
test, which the tests of the Kubernetes pods put to each pod too."""

from __future__ import annotations

import importlib.util
from types import ModuleType

from oricf.config import REPO_ROOT


def smoke_check() -> ModuleType:
    spec = importlib.util.spec_from_file_location("smoke_check", REPO_ROOT / "compose" /
                                                  "smoke_check.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
