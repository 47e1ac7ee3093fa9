"""Links the folders that make up the `oricf` namespace into one tree: `python
scripts/namespace_view.py DIR`, then tools that walk a package's files see DIR/oricf.

pyproject.toml maps top-level folders (services/, gateway/, bench/, protos/oricf/v1...) onto
`oricf.*` with package-dir. Python imports them through that mapping, but a tool that reads
the files of `oricf` from disk (grimp, and so import-linter) finds only the oricf/ folder.
In DIR/oricf every entry of oricf/ and every mapped folder is a symbolic link to the
checkout, so a tool that finds `oricf` in DIR sees the namespace exactly as Python imports
it. scripts/test.sh runs `lint-imports` in DIR (it puts its working directory first on
sys.path); tests/test_layers.py runs grimp with PYTHONPATH=DIR.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "oricf"


def package_dirs(root: Path = ROOT) -> dict[str, Path]:
    """[tool.setuptools] package-dir: package name -> its folder in the checkout."""
    with (root / "pyproject.toml").open("rb") as file:
        mapping = tomllib.load(file)["tool"]["setuptools"]["package-dir"]
    return {name: root / folder for name, folder in mapping.items()}


def build_view(target: Path, root: Path = ROOT) -> Path:
    """Fills target/oricf with links (target must be empty or missing); returns target/oricf."""
    folders = package_dirs(root)
    view = target / PACKAGE
    view.mkdir(parents=True)
    for entry in sorted(folders[PACKAGE].iterdir()):
        if entry.name != "__pycache__":
            (view / entry.name).symlink_to(entry)
    for name, folder in sorted(folders.items()):
        if name == PACKAGE:
            continue
        parts = name.split(".")
        if parts[0] != PACKAGE or len(parts) != 2:
            raise ValueError(f"package-dir {name!r}: only oricf.NAME folders are linked")
        link = view / parts[1]
        if link.exists():
            raise ValueError(f"package-dir {name!r}: oricf/{parts[1]} exists already")
        link.symlink_to(folder)
    return view


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("target", type=Path, help="an empty or missing directory")
    args = parser.parse_args(argv)
    build_view(args.target)
    return 0


if __name__ == "__main__":
    sys.exit(main())
