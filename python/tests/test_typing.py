"""The package's type hints (inline, and _native.pyi for the compiled module) are consistent:
mypy --strict accepts the installed package."""

from __future__ import annotations

import subprocess
import sys


def test_mypy_strict_accepts_the_package():
    proc = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "--no-incremental", "-p", "poseboard"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
