"""Result files and rows: the checks of `poseboard check-results`, with every problem named by
its line, and rows in memory (bop_toolkit's dicts, numpy structured arrays) scored like the file
they come from."""

from __future__ import annotations

import json

import numpy as np
import pytest

import poseboard
from conftest import DATASET, RESULTS, result_file

# What each malformed file must be refused with (tests/fixtures/reference/results/malformed/README.md).
MALFORMED = {
    "bad-header_synthA-test.csv": (1, "bad header on line 1"),
    "nan_synthA-test.csv": (4, "non-finite number on line 4"),
    "not-rotation_synthA-test.csv": (5, "R on line 5 is not a rotation matrix"),
    "wrong-columns_synthA-test.csv": (6, "line 6 has 6 fields, expected 7"),
    "inconsistent-time_synthA-test.csv": (3, "line 3: time"),
}


@pytest.mark.parametrize("file", sorted(MALFORMED))
def test_a_malformed_file_raises_value_error_naming_its_line(dataset, file):
    line, message = MALFORMED[file]
    path = RESULTS / "malformed" / file
    with pytest.raises(ValueError, match=f"{file} is not a valid result file") as check:
        poseboard.check_results(path)
    assert message in str(check.value)
    assert [n for n, _ in check.value.problems] == [line]
    with pytest.raises(ValueError) as ev:
        poseboard.evaluate(dataset, path)
    assert message in str(ev.value)


def test_the_inconsistent_time_names_the_image():
    with pytest.raises(ValueError) as e:
        poseboard.check_results(RESULTS / "malformed" / "inconsistent-time_synthA-test.csv")
    assert "scene 1, image 0" in str(e.value)


def test_check_results_counts_and_reports_coverage(dataset):
    path = result_file("missing_synthA-test")
    alone = poseboard.check_results(path)
    report = poseboard.evaluate(dataset, path)
    assert alone["estimates"] == report["estimates_count"]
    with_dataset = poseboard.check_results(path, DATASET)
    assert with_dataset == poseboard.check_results(path, dataset)
    assert with_dataset["targets"] == len(
        json.loads((DATASET / "test_targets_bop19.json").read_text())
    )
    assert with_dataset["targets_without_estimate"] == report["targets_without_estimate"] > 0
    assert with_dataset["estimates_ignored"] == report["estimates_ignored"]


def test_a_missing_file_raises_file_not_found(dataset):
    with pytest.raises(FileNotFoundError):
        poseboard.check_results(RESULTS / "no-such-file.csv")
    with pytest.raises(FileNotFoundError):
        poseboard.evaluate(dataset, RESULTS / "no-such-file.csv")
    with pytest.raises(FileNotFoundError, match="cannot load the dataset"):
        poseboard.evaluate(RESULTS / "no-such-dataset", result_file("gtexact_synthA-test"))


def bop_toolkit_rows(name: str) -> list[dict]:
    """A result file as bop_toolkit's inout.load_bop_results returns it."""
    rows = []
    for line in result_file(name).read_text().splitlines()[1:]:
        e = line.split(",")
        rows.append(
            {
                "scene_id": int(e[0]),
                "im_id": int(e[1]),
                "obj_id": int(e[2]),
                "score": float(e[3]),
                "R": np.array(list(map(float, e[4].split())), np.float64).reshape((3, 3)),
                "t": np.array(list(map(float, e[5].split())), np.float64).reshape((3, 1)),
                "time": float(e[6]),
            }
        )
    return rows


@pytest.mark.parametrize("protocol", ["bop19", "eccv18"])
def test_rows_score_like_their_file(dataset, protocol):
    name = "multi_synthA-test"
    from_file = poseboard.evaluate(dataset, result_file(name), protocol)
    assert poseboard.evaluate(dataset, bop_toolkit_rows(name), protocol) == from_file
    # A generator, too, and rows without a time (bop_toolkit's save_bop_results writes -1).
    rows = bop_toolkit_rows(name)
    no_time = poseboard.evaluate(
        dataset, ({k: v for k, v in r.items() if k != "time"} for r in rows), protocol
    )
    assert no_time["per_error_recall_per_threshold"] == from_file["per_error_recall_per_threshold"]
    if protocol == "bop19":
        # bop_toolkit writes -1 when the file gives no times.
        assert no_time["bop19_average_time_per_image"] == -1
    else:
        assert "bop19_average_time_per_image" not in no_time


def test_a_structured_array_scores_like_its_file(dataset):
    name = "noisemedium_synthA-test"
    rows = bop_toolkit_rows(name)
    dtype = [
        ("scene_id", "i4"),
        ("im_id", "i4"),
        ("obj_id", "i4"),
        ("score", "f8"),
        ("R", "f8", (3, 3)),
        ("t", "f8", (3,)),
        ("time", "f8"),
    ]
    array = np.array(
        [
            (r["scene_id"], r["im_id"], r["obj_id"], r["score"], r["R"], r["t"].ravel(), r["time"])
            for r in rows
        ],
        dtype=dtype,
    )
    assert poseboard.evaluate(dataset, array) == poseboard.evaluate(dataset, result_file(name))


def test_invalid_rows_raise_value_error_naming_every_row(dataset):
    rows = bop_toolkit_rows("noisesmall_synthA-test")
    rows[2]["t"] = np.array([0.0, np.nan, 500.0])
    rows[4]["R"] = rows[4]["R"] * 1.5
    rows[5]["scene_id"] = -1
    with pytest.raises(ValueError) as e:
        poseboard.evaluate(dataset, rows)
    assert [line for line, _ in e.value.problems] == [3, 5, 6]
    assert "row i is line i + 1" in str(e.value)
    rows = bop_toolkit_rows("noisesmall_synthA-test")
    rows[7]["R"] = np.eye(2)
    with pytest.raises(ValueError, match="row 7: R has 4 numbers, expected 9"):
        poseboard.evaluate(dataset, rows)
    del rows[7]["R"]
    with pytest.raises(ValueError, match="row 7 has no 'R'"):
        poseboard.evaluate(dataset, rows)
