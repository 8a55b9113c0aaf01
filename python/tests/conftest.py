"""Shared fixtures: the repository's paths and the skinpatch binary the
Python results are compared with."""

import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def binary() -> pathlib.Path:
    """The release binary (`cargo test --release` or `cargo build --release`
    builds it; SKINPATCH_BIN names another)."""
    if "SKINPATCH_BIN" in os.environ:
        return pathlib.Path(os.environ["SKINPATCH_BIN"])
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    return target / "release" / "skinpatch"


@pytest.fixture(scope="session")
def root() -> pathlib.Path:
    return ROOT


@pytest.fixture(scope="session")
def run_binary():
    """Runs `skinpatch run SCENARIO -o DIR [--set k=v ...]`."""
    exe = binary()
    if not exe.exists():
        pytest.fail(f"{exe} is missing: build it with `cargo build --release` first")

    def run(scenario, out, *sets):
        args = [str(exe), "run", "-q", str(scenario), "-o", str(out)]
        for s in sets:
            args += ["--set", s]
        subprocess.run(args, check=True, cwd=ROOT)
        return out

    return run
