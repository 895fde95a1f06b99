"""The benchmark command."""

from __future__ import annotations

import json

import pytest


@pytest.mark.slow
@pytest.mark.realdata
def test_benchmark_command_writes_json_markdown_and_plots(shared_data, tmp_path, capsys):
    from o3d_rpointhop.cli import main

    args = [
        "benchmark",
        "modelnet40",
        "--data",
        str(shared_data),
        "--output",
        str(tmp_path),
        "--max-shapes",
        "2",
        "--protocol",
        "paper",
        "resampled",
        "angle-sweep",
        "--methods",
        "rpointhop-ransac-icp,icp",
        "--no-progress",
    ]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "## resampled" in out and "R-PointHop + RANSAC + point-to-plane ICP" in out
    results = json.loads((tmp_path / "modelnet40.json").read_text())
    paper = results["protocols"]["paper"]["summary"]
    assert paper["rpointhop-ransac-icp"]["success_rate"] == 1.0
    assert set(results["protocols"]["angle-sweep"]["summary"]) == {
        "0",
        "15",
        "30",
        "45",
        "60",
        "90",
        "120",
        "150",
        "180",
    }
    assert (tmp_path / "modelnet40_success_rate.png").stat().st_size > 1000
    assert (tmp_path / "modelnet40_angle-sweep.png").stat().st_size > 1000
    # repeatable: the same seed gives the same numbers
    main(args)
    again = json.loads((tmp_path / "modelnet40.json").read_text())
    for method in ("rpointhop-ransac-icp", "icp"):
        first = results["protocols"]["resampled"]["records"][method]
        second = again["protocols"]["resampled"]["records"][method]
        assert [r["rotation_error_deg"] for r in first] == [r["rotation_error_deg"] for r in second]


@pytest.mark.slow
@pytest.mark.realdata
def test_benchmark_3dmatch_command_records_every_method_on_the_same_pairs(
    shared_data, tmp_path, capsys
):
    from o3d_rpointhop.cli import main

    methods = ["rpointhop-scene", "fpfh-pipeline-consensus-icp"]
    args = ["benchmark", "3dmatch", "--data", str(shared_data), "--scenes", "redkitchen"]
    args += ["--max-pairs", "1", "--methods", ",".join(methods), "--output", str(tmp_path)]
    assert main([*args, "--no-progress"]) == 0
    assert "written:" in capsys.readouterr().out
    results = json.loads((tmp_path / "3dmatch.json").read_text())
    assert set(results["protocols"]) == {"3DMatch", "3DLoMatch"}
    for benchmark in results["protocols"].values():
        assert set(benchmark["summary"]) == set(methods)
        pairs = [[r["pair"] for r in benchmark["records"][m]] for m in methods]
        assert len(pairs[0]) == 1 and pairs[0] == pairs[1]  # the same pair for both
        record = benchmark["records"]["rpointhop-scene"][0]
        assert 0.0 <= record["diagnostics"]["support"] <= 1.0
        assert "seconds" not in json.dumps(benchmark["records"])  # times are kept apart
    scene = results["provenance"]["methods"]["rpointhop-scene"]["descriptor"]
    assert scene["model"] == "scene" and scene["n_features_out"] == 96
    timings = json.loads((tmp_path / "3dmatch_timings.json").read_text())["protocols"]
    for name, benchmark in timings.items():
        for method in methods:
            assert benchmark["records"][method][0]["seconds"] > 0, (name, method)
    assert (tmp_path / "3dmatch_registration_recall.png").stat().st_size > 1000


def test_benchmark_command_rejects_bad_choices(capsys):
    from o3d_rpointhop.cli import main

    assert main(["benchmark", "3dmatch", "--protocol", "x"]) == 1
    assert "no protocols" in capsys.readouterr().err
    # Options of one benchmark given to another, and objects the scan-set benchmark
    # does not have: refused before any data is read.
    for args, message in (
        (["benchmark", "modelnet40", "--rotate"], "--rotate applies to 3dmatch"),
        (["benchmark", "bunny", "--with-consecutive"], "apply to 3dmatch"),
        (["benchmark", "modelnet40", "--viewpoints", "none"], "apply to 3dmatch"),
        (["benchmark", "multiway", "--protocol", "teapot"], "multiway objects are"),
    ):
        assert main([*args, "--data", "/nowhere"]) == 1, args
        assert message in capsys.readouterr().err, args
