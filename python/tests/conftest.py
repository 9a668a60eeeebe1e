"""Shared fixtures of the Python package's tests: the repository, the command line built from the
same crate (to compare against), the real vessels.

Under CI (``CI=true``) a missing command line, vessels folder, meshio or PyVista is a failure;
elsewhere the tests that need them are skipped with the reason."""

import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def under_ci() -> bool:
    return os.environ.get("CI") in ("true", "1")


def need(what: str, present: bool) -> None:
    """Fails under CI, skips elsewhere, when something a test needs is missing."""
    if not present:
        if under_ci():
            pytest.fail(f"CI=true but {what} is missing")
        pytest.skip(f"{what} is missing")


def require(module: str):
    """The module, imported; missing, a failure under CI and a skip elsewhere."""
    try:
        return __import__(module)
    except ImportError:
        need(f"the Python package {module}", False)


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO


@pytest.fixture(scope="session")
def cli() -> Path:
    """The ``vesselhex`` command built from this checkout (``VESSELHEX_BIN`` overrides)."""
    path = Path(os.environ.get("VESSELHEX_BIN", REPO / "target" / "release" / "vesselhex"))
    need(f"the vesselhex command ({path}; cargo build --release)", path.is_file())
    return path


@pytest.fixture(scope="session")
def vessels() -> Path:
    path = Path(os.environ.get("VESSELHEX_VESSELS", REPO.parent / "shared" / "vessels"))
    need(f"the real vessels ({path}; set VESSELHEX_VESSELS)", (path / "manifest.json").is_file())
    return path


def run_cli(cli: Path, *args: str, check: bool = True) -> subprocess.CompletedProcess:
    done = subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True)
    if check and done.returncode != 0:
        raise AssertionError(f"vesselhex {' '.join(map(str, args))} failed: {done.stderr}")
    return done
