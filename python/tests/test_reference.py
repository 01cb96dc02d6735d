"""poseboard.evaluate reproduces every score bop_toolkit computed on the reference set
(tests/fixtures/reference), with the tolerances of the Rust tests (evaluator/tests/reference.rs):
recalls and counts exactly, average recalls to 1e-6."""

from __future__ import annotations

import pytest

import poseboard
from conftest import DATASET, RESULT_NAMES, expected, result_file


@pytest.mark.parametrize("name", RESULT_NAMES)
@pytest.mark.parametrize("visib_mode", ["bop19", "bop18"])
def test_eccv18_recalls_match_bop_toolkit(dataset, name, visib_mode):
    report = poseboard.evaluate(dataset, result_file(name), "eccv18", visib_mode=visib_mode)
    want = expected(name, f"ecc18_{visib_mode}vis.json")
    for key in [
        "recall",
        "tp_count",
        "targets_count",
        "gt_count",
        "obj_recalls",
        "scene_recalls",
        "mean_obj_recall",
    ]:
        assert report[key] == want[key], key


@pytest.mark.parametrize("name", RESULT_NAMES)
def test_bop19_scores_match_bop_toolkit(dataset, name):
    report = poseboard.evaluate(dataset, result_file(name))
    want = expected(name, "bop19.json")
    for key in [
        "bop19_average_recall",
        "bop19_average_recall_vsd",
        "bop19_average_recall_mssd",
        "bop19_average_recall_mspd",
        "bop19_average_time_per_image",
    ]:
        assert report[key] == pytest.approx(want[key], abs=1e-6), key
    # Every recall behind the averages, exactly.
    assert report["per_error_recall_per_threshold"] == want["per_error_recall_per_threshold"]


@pytest.mark.parametrize("name", ["noisemedium_synthA-test", "symflip_synthA-test"])
@pytest.mark.parametrize("error", ["ad", "add", "adi"])
def test_add_adi_and_ad_recalls_match_bop_toolkit(dataset, name, error):
    # bop_toolkit scored these with n_top -1, visib_gt_min -1 and threshold 0.1 x diameter:
    # bop19's selection, with the error added to its three.
    report = poseboard.evaluate(dataset, result_file(name), extra_errors=[error], ad_threshold=0.1)
    want = expected(name, "errors", error, "scores_th=0.100_min-visib=-1.000.json")
    got = report["per_error_recall_per_threshold"][f"error={error}_ntop=-1"]
    assert got == {"th=0.100_min-visib=-1.000": want["recall"]}
    assert report["average_recalls"][error] == want["recall"]


def test_a_dataset_folder_and_a_loaded_dataset_give_the_same_report(dataset):
    path = result_file("multi_synthA-test")
    assert poseboard.evaluate(DATASET, path) == poseboard.evaluate(dataset, path)


def test_estimates_for_non_targets_are_ignored_and_reported(dataset):
    small = poseboard.evaluate(dataset, result_file("noisesmall_synthA-test"))
    extra = poseboard.evaluate(dataset, result_file("extra_synthA-test"))
    assert small["bop19_average_recall"] == extra["bop19_average_recall"]
    # `extra` adds one estimate for each object absent from an image.
    assert extra["estimates_ignored"] == small["estimates_ignored"] + 3
    assert any("not test targets" in w for w in extra["warnings"])
