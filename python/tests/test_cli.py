"""`poseboard-eval` is `poseboard eval`: for the same arguments it prints the same table and
writes byte for byte the same --out and --errors-out JSON as the service's command."""

from __future__ import annotations

import shutil

import pytest

from conftest import DATASET, RESULTS, result_file, run_eval


def python_eval(args, tmp_path):
    command = shutil.which("poseboard-eval")
    assert command is not None, "the poseboard-eval script is not installed"
    return run_eval([command], args, tmp_path)


CASES = {
    "bop19": ["--results", str(result_file("noisemedium_synthA-test"))],
    "eccv18": ["--results", str(result_file("multi_synthA-test")), "--protocol", "eccv18"],
    "eccv18-overrides": [
        "--results",
        str(result_file("symflip_synthA-test")),
        "--protocol",
        "eccv18",
        "--tau",
        "20,40",
        "--tau",
        "60",
        "--theta",
        "0.2,0.3",
        "--delta",
        "10",
        "--visib-mode",
        "bop18",
        "--visib-gt-min",
        "0",
        "--n-top",
        "-1",
    ],
    "bop19-overrides": [
        "--results",
        str(result_file("extra_synthA-test")),
        "--threads",
        "1",
        "--extra-errors",
        "add,adi",
        "--extra-errors",
        "ad",
        "--ad-threshold",
        "0.2",
        "--tau",
        "0.1,0.3",
        "--tau-normalized",
        "true",
        "--theta",
        "0.25",
        "--n-top",
        "0",
        "--max-sym-disc-step",
        "0.02",
    ],
    "bop19-no-estimate-for-a-target": ["--results", str(result_file("missing_synthA-test"))],
}


@pytest.mark.parametrize("case", list(CASES))
def test_poseboard_eval_prints_and_writes_what_the_rust_command_does(rust_eval, tmp_path, case):
    args = ["--dataset", str(DATASET)] + CASES[case]
    rust = rust_eval(args)
    assert rust.returncode == 0, rust.stderr
    mine = python_eval(args, tmp_path)
    assert mine.returncode == 0, mine.stderr
    assert mine.out == rust.out
    assert mine.errors == rust.errors
    assert mine.stdout == rust.stdout
    assert mine.stderr == rust.stderr


def test_poseboard_eval_refuses_a_malformed_file_naming_its_line(rust_eval, tmp_path):
    args = [
        "--dataset",
        str(DATASET),
        "--results",
        str(RESULTS / "malformed" / "wrong-columns_synthA-test.csv"),
    ]
    mine = python_eval(args, tmp_path)
    rust = rust_eval(args)
    assert mine.returncode == rust.returncode == 1
    assert "line 6 has 6 fields, expected 7" in mine.stderr
    assert mine.out is None


@pytest.mark.parametrize(
    "bad",
    [
        ["--protocol", "bop20"],
        ["--tau-normalized", "yes"],
        ["--extra-errors", "vsd"],
        ["--n-top", "-2"],
    ],
)
def test_poseboard_eval_refuses_what_poseboard_eval_refuses(rust_eval, tmp_path, bad):
    args = ["--dataset", str(DATASET), "--results", str(result_file("gtexact_synthA-test"))] + bad
    assert rust_eval(args).returncode != 0
    assert python_eval(args, tmp_path).returncode != 0
