"""The parts of evaluate() beyond the report: progress, cancellation by the callback, threads,
and parameter checks."""

from __future__ import annotations

import pytest

import poseboard
from conftest import result_file


def test_progress_reports_every_evaluated_estimate(dataset):
    calls = []
    report = poseboard.evaluate(
        dataset,
        result_file("multi_synthA-test"),
        progress=lambda done, total: calls.append((done, total)),
    )
    n = report["estimates_evaluated"]
    assert calls[-1] == (n, n)
    assert all(total == n for _, total in calls)
    assert [done for done, _ in calls] == sorted(done for done, _ in calls)


def test_an_exception_in_the_progress_callback_stops_the_evaluation(dataset):
    def stop(done, total):
        raise KeyError("stop")

    with pytest.raises(KeyError, match="stop"):
        poseboard.evaluate(dataset, result_file("multi_synthA-test"), progress=stop)


def test_the_number_of_threads_does_not_change_the_report(dataset):
    path = result_file("noisemedium_synthA-test")
    assert poseboard.evaluate(dataset, path, threads=1) == poseboard.evaluate(
        dataset, path, threads=2
    )


@pytest.mark.parametrize(
    "params, message",
    [
        ({"protocol": "bop20"}, "unknown protocol"),
        ({"n_top": -2}, "n_top"),
        ({"visib_mode": "bop17"}, "visibility mode"),
        ({"extra_errors": ["vsd"]}, "unknown extra error"),
        ({"theta": []}, "thresholds"),
        ({"max_sym_disc_step": 0}, "max_sym_disc_step"),
    ],
)
def test_invalid_parameters_raise_value_error(dataset, params, message):
    with pytest.raises(ValueError, match=message):
        poseboard.evaluate(dataset, result_file("gtexact_synthA-test"), **params)


def test_the_report_names_the_evaluator_and_the_parameters(dataset):
    report = poseboard.evaluate(
        dataset, result_file("gtexact_synthA-test"), "eccv18", tau=30, theta=[0.2]
    )
    assert report["evaluator_version"] == poseboard.EVALUATOR_VERSION
    assert report["protocol"] == "eccv18"
    assert report["parameters"]["main_tau"] == 30
    assert report["parameters"]["main_theta"] == 0.2
    assert report["recall"] == 1.0
