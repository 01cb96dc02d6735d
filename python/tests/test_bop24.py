"""protocol="bop24" (BOP'24 6D detection) against the scores bop_toolkit's eval_bop24_pose.py
computed on tests/fixtures/bop24, and against `poseboard eval --protocol bop24`."""

from __future__ import annotations

import json
import pathlib
import shutil
import subprocess

import pytest

import poseboard
from conftest import DATASET, ROOT, poseboard_bin

BOP24 = ROOT / "tests" / "fixtures" / "bop24"
TARGETS = BOP24 / "test_targets_bop24.json"
CASES = ["gtexact", "noisy", "extra", "ties", "capped"]
KEYS = [
    "bop24_mAP",
    "bop24_mAP_mssd",
    "bop24_mAP_mssd_mm",
    "bop24_mAP_mspd",
    "bop25_mAP",
    "bop25_mAP_mm",
    "bop24_average_time_per_image",
]


def result_file(case: str) -> pathlib.Path:
    return BOP24 / "results" / f"{case}_synthA-test.csv"


def expected(case: str) -> dict:
    return json.loads((BOP24 / "expected" / f"{case}.json").read_text())


@pytest.fixture(scope="module")
def detection_dataset() -> poseboard.Dataset:
    return poseboard.Dataset(DATASET, targets_file=str(TARGETS))


@pytest.mark.parametrize("case", CASES)
def test_bop24_scores_match_bop_toolkit(detection_dataset, case):
    report = poseboard.evaluate(detection_dataset, result_file(case), "bop24")
    want = expected(case)
    for key in KEYS:
        assert report[key] == pytest.approx(want[key], abs=1e-9), key
    for scores in report["errors"]:
        table = want["per_threshold"][scores["error"]]
        for t, threshold in enumerate(scores["thresholds"]):
            theirs = table[f"th={threshold:.3f}_min-visib=0.100"]
            for o in scores["objects"]:
                assert o["ap_per_threshold"][t] == pytest.approx(theirs[str(o["obj_id"])], abs=1e-9)


@pytest.mark.parametrize("layout", ["ipd", "xyzibd"])
@pytest.mark.parametrize("case", CASES)
def test_industrial_layouts_match_bop_toolkit(layout, case):
    # The reference scenes laid out as IPD and XYZ-IBD (the evaluated sensor's files, its
    # published width for MSPD, XYZ-IBD's cap of 200), scored by the toolkit as those datasets.
    report = poseboard.evaluate(BOP24 / "datasets" / layout,
                                BOP24 / "results" / f"{case}_{layout}-test.csv", "bop24")
    want = json.loads((BOP24 / "expected" / layout / f"{case}.json").read_text())
    for key in KEYS:
        assert report[key] == pytest.approx(want[key], abs=1e-9), key
    assert report["parameters"]["max_estimates_per_image"] == (200 if layout == "xyzibd" else 100)


def test_a_folder_is_read_with_its_bop24_targets(tmp_path):
    folder = tmp_path / "synthA"
    shutil.copytree(DATASET, folder, ignore=shutil.ignore_patterns("rgb", "depth"))
    shutil.copy(TARGETS, folder / "test_targets_bop24.json")
    report = poseboard.evaluate(folder, result_file("noisy"), "bop24", max_estimates_per_image=2)
    assert report["parameters"]["max_estimates_per_image"] == 2
    assert report["estimates_beyond_cap"] > 0
    out = tmp_path / "report.json"
    subprocess.run(
        [str(poseboard_bin()), "eval", "--dataset", str(folder), "--results",
         str(result_file("noisy")), "--protocol", "bop24", "--max-estimates-per-image", "2",
         "--out", str(out)],
        check=True, capture_output=True, timeout=600,
    )
    assert json.loads(out.read_text()) == report


def test_bop24_refuses_what_does_not_apply(detection_dataset, dataset):
    with pytest.raises(ValueError, match="bop24 has fixed errors and thresholds"):
        poseboard.evaluate(detection_dataset, result_file("noisy"), "bop24", tau=0.2)
    with pytest.raises(ValueError, match='max_estimates_per_image is for protocol="bop24" only'):
        poseboard.evaluate(dataset, result_file("noisy"), "bop19", max_estimates_per_image=5)
    with pytest.raises(ValueError, match="a list of images"):
        poseboard.evaluate(detection_dataset, result_file("noisy"), "bop19")
    with pytest.raises(ValueError, match="time 0.25 for scene 1, image 0 differs from 0.5"):
        poseboard.evaluate(detection_dataset, result_file("twotimes"), "bop24")
