"""Shared fixtures: the real scenes of ../shared/data, the `verisplat` command-line binary
(VERISPLAT_BIN, or the repository's target/debug or target/release build) and one GPU
renderer for the session."""

import os
import pathlib
import subprocess
import sys

import pytest

# `cd python && python -m pytest` puts python/ first on sys.path, where the package's
# source (without its compiled extension) would shadow the installed package the tests
# are for: take it out, so the tests run the same from the repository root and from here.
_SOURCE = pathlib.Path(__file__).resolve().parents[1]
sys.path[:] = [p for p in sys.path if pathlib.Path(p or ".").resolve() != _SOURCE]
sys.modules.pop("verisplat", None)

import verisplat  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data"


def data(name: str) -> pathlib.Path:
    path = DATA / name
    if not path.exists():
        pytest.fail(f"test data {path} is missing (the read-only ../shared/data folder)")
    return path


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    env = os.environ.get("VERISPLAT_BIN")
    candidates = [pathlib.Path(env)] if env else [
        REPO / "target" / "debug" / "verisplat",
        REPO / "target" / "release" / "verisplat",
    ]
    for c in candidates:
        if c.is_file():
            return c
    pytest.fail(
        "the verisplat binary was not found (build it with `cargo build`, or set VERISPLAT_BIN); "
        f"looked at {', '.join(map(str, candidates))}"
    )


def run_cli(binary: pathlib.Path, *args: str) -> subprocess.CompletedProcess:
    proc = subprocess.run([str(binary), *map(str, args)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise AssertionError(f"verisplat {' '.join(map(str, args))} failed:\n{proc.stderr}")
    return proc


@pytest.fixture(scope="session")
def renderer() -> verisplat.Renderer:
    return verisplat.Renderer()


@pytest.fixture(scope="session")
def lod3() -> verisplat.Scene:
    return verisplat.load(data("playbot_lod3_31k_sh2.ply"))


@pytest.fixture(scope="session")
def demo() -> verisplat.Scene:
    return verisplat.demo()
