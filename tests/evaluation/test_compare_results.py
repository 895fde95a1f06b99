"""benchmarks/compare_results.py: what a rerun changed, pair by pair."""

from __future__ import annotations

import pytest
from helpers import benchmark_script


@pytest.fixture(scope="module")
def compare_results():
    return benchmark_script("compare_results")


def _record(pair, rotation, translation, symmetric=None):
    row = {"pair": pair, "rotation_error_deg": rotation, "translation_error": translation}
    if symmetric is not None:
        row["symmetric"] = symmetric
    return row


def test_counts_gains_and_losses_on_the_pairs_both_hold(compare_results):
    old = {
        "protocols": {
            "p": {
                "records": {
                    "m": [
                        _record("a", 1.0, 0.01, False),
                        _record("b", 90.0, 0.5, True),
                        _record("c", 1.0, 0.01, False),
                        _record("gone", 1.0, 0.01, False),
                    ]
                }
            }
        }
    }
    new = {
        "protocols": {
            "p": {
                "records": {
                    "m": [
                        _record("a", 1.0, 0.01, False),
                        _record("b", 1.0, 0.01, False),  # gained
                        _record("c", 1.0, 0.06, False),  # lost: translation 0.06 > 0.05
                    ]
                }
            }
        }
    }
    (row,) = compare_results.compare(old, new)
    assert (row["pairs"], row["before"], row["after"]) == (3, 2, 2)
    assert (row["gained"], row["lost"]) == (1, 1)
    assert (row["before_up_to_symmetry"], row["after_up_to_symmetry"]) == (3, 2)
    assert row["p_value"] == 1.0


def test_a_protocol_in_millimetres_is_read_in_metres(compare_results):
    protocol = {"success": "rotation error < 2.0 deg and translation error < 2.0 mm"}
    assert compare_results._tolerance(protocol) == (2.0, 0.002)
    assert compare_results._tolerance({}) == (5.0, 0.05)
    old = {"protocols": {"s": {**protocol, "records": {"m": [_record("x", 0.1, 0.003)]}}}}
    new = {"protocols": {"s": {**protocol, "records": {"m": [_record("x", 0.1, 0.0015)]}}}}
    (row,) = compare_results.compare(old, new)
    assert (row["before"], row["after"], row["gained"]) == (0, 1, 1)
    assert row["before_up_to_symmetry"] is None
    assert "| s | m | 1 | 0 | 1 | - | 1 / 0 |" in compare_results.markdown([row])
