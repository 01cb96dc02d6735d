"""Shared paths and runs: the reference fixtures of the repository (bop_toolkit's numbers) and
the `poseboard` command of the service, whose output the package must reproduce."""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
from typing import Any

import pytest

import poseboard

ROOT = pathlib.Path(__file__).resolve().parents[2]
FIXTURES = ROOT / "tests" / "fixtures" / "reference"
DATASET = FIXTURES / "dataset"
RESULTS = FIXTURES / "results"
EXPECTED = FIXTURES / "expected"

RESULT_NAMES = [
    "extra_synthA-test",
    "gtexact_synthA-test",
    "missing_synthA-test",
    "multi_synthA-test",
    "noiselarge_synthA-test",
    "noisemedium_synthA-test",
    "noisesmall_synthA-test",
    "random_synthA-test",
    "symflip_synthA-test",
]


def result_file(name: str) -> pathlib.Path:
    return RESULTS / f"{name}.csv"


def expected(name: str, *parts: str) -> Any:
    return json.loads(EXPECTED.joinpath(name, *parts).read_text())


@pytest.fixture(scope="session")
def dataset() -> poseboard.Dataset:
    return poseboard.Dataset(DATASET)


def poseboard_bin() -> pathlib.Path:
    """The `poseboard` command built from this repository (`cargo build -p server`);
    POSEBOARD_BIN overrides the path."""
    path = pathlib.Path(os.environ.get("POSEBOARD_BIN", ROOT / "target" / "debug" / "poseboard"))
    if not path.is_file():
        pytest.fail(f"{path} does not exist: run `cargo build -p server` or set POSEBOARD_BIN")
    return path


class CliRun:
    """One `poseboard eval` run of the Rust command: exit code, stdout, stderr, and the
    texts it wrote with --out and --errors-out."""

    def __init__(
        self, returncode: int, stdout: str, stderr: str, out: str | None, errors: str | None
    ):
        self.returncode = returncode
        self.stdout = stdout
        self.stderr = stderr
        self.out = out
        self.errors = errors


def run_eval(command: list[str], args: list[str], tmp: pathlib.Path) -> CliRun:
    """Runs an eval command (the Rust `poseboard eval` or `poseboard-eval`) with --out and
    --errors-out in `tmp`."""
    tmp.mkdir(parents=True, exist_ok=True)
    out, errors = tmp / "out.json", tmp / "errors.json"
    proc = subprocess.run(
        command + args + ["--out", str(out), "--errors-out", str(errors)],
        capture_output=True,
        text=True,
        timeout=600,
    )

    def read(path: pathlib.Path) -> str | None:
        return path.read_text() if path.exists() else None

    return CliRun(proc.returncode, proc.stdout, proc.stderr, read(out), read(errors))


_rust_runs: dict[tuple[str, ...], CliRun] = {}


@pytest.fixture(scope="session")
def rust_eval(tmp_path_factory: pytest.TempPathFactory):
    """`poseboard eval` of the service on the given arguments, run once per argument list."""

    def run(args: list[str]) -> CliRun:
        key = tuple(args)
        if key not in _rust_runs:
            tmp = tmp_path_factory.mktemp("rust-eval")
            _rust_runs[key] = run_eval([str(poseboard_bin()), "eval"], args, tmp)
        return _rust_runs[key]

    return run
