"""The package reads a dataset's prepared form (made by `poseboard dataset prepare`) when it is
there and current, gives the same report to the bit, and warns about one it cannot use."""

from __future__ import annotations

import json
import pathlib
import shutil
import subprocess
import warnings

import pytest

import poseboard
from conftest import DATASET, poseboard_bin, result_file


def test_a_prepared_dataset_gives_the_same_report_and_an_unusable_one_warns(
    tmp_path: pathlib.Path,
) -> None:
    dataset = tmp_path / "synthA"
    shutil.copytree(DATASET, dataset)
    results = result_file("noisemedium_synthA-test")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plain = poseboard.evaluate(dataset, results, "bop19")
    subprocess.run([str(poseboard_bin()), "dataset", "prepare", str(dataset)], check=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert poseboard.evaluate(dataset, results, "bop19") == plain
        assert poseboard.evaluate(dataset, results, "bop19", unprepared=True) == plain

    one = dataset / "poseboard_prepared" / "000002" / "000000.pbprep"
    one.write_bytes(one.read_bytes()[:-10])
    with pytest.warns(UserWarning, match=r"000000\.pbprep: truncated"):
        assert poseboard.evaluate(dataset, results, "bop19") == plain

    manifest = dataset / "poseboard_prepared" / "manifest.json"
    stale = json.loads(manifest.read_text())
    stale["evaluator"] = "0.0.1 format 0"
    manifest.write_text(json.dumps(stale))
    with pytest.warns(UserWarning, match="stale: made by evaluator 0.0.1"):
        assert poseboard.evaluate(dataset, results, "bop19") == plain
