"""Shared fixtures: the repository, the command-line program the Python results are held
against, and the test scenes."""

import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def repo() -> pathlib.Path:
    return REPO


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    """The `pathgrad` program (PATHGRAD_BIN, else the debug build that `cargo test` leaves)."""
    path = pathlib.Path(os.environ.get("PATHGRAD_BIN", REPO / "target" / "debug" / "pathgrad"))
    if not path.is_file():
        pytest.fail(f"{path} is missing: build it with `cargo build` or set PATHGRAD_BIN")
    return path


@pytest.fixture(scope="session")
def run_cli(cli):
    def run(*args: str) -> str:
        done = subprocess.run([str(cli), *args], capture_output=True, text=True)
        assert done.returncode == 0, f"pathgrad {' '.join(args)} failed:\n{done.stderr}"
        return done.stdout

    return run

