"""The package build ships every subpackage: ``pyproject.toml`` lists its packages by
name, so a new folder left out of the list would import in the editable checkout and fail
in a user's ``pip install .``."""

from __future__ import annotations

import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent


def test_every_subpackage_is_listed_in_the_build() -> None:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    mapped = {str(Path(path)): name for name, path in config.get("package-dir", {}).items()}
    on_disk = set()
    for top in ("orthoglide_env", "calibrators", *mapped):
        for init in (ROOT / top).rglob("__init__.py"):
            folder = str(init.parent.relative_to(ROOT))
            on_disk.add(mapped.get(folder, folder.replace("/", ".")))
    assert on_disk <= listed, f"packages missing from pyproject.toml: {sorted(on_disk - listed)}"
