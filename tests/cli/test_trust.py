"""The command line says when a result is not to be trusted: a distinct exit status,
one line on stderr, and the verdict in ``--json``; warnings are one line each;
transformations are written with every digit and read back from every form
``register`` writes; options are not abbreviated."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from o3d_rpointhop.cli import EXIT_OK, EXIT_UNTRUSTED, EXIT_USAGE, main
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration import RegistrationResult
from o3d_rpointhop.registration.defaults import TRUST_SUPPORT

SURVEY = np.array([452_310.0, 5_211_870.0, 312.0])
# Two scans of an asymmetric object, one turned and moved: registered, converged and
# unambiguous with the defaults.
TARGET = make_object(2000, shape_seed=5, sample_seed=1)
SOURCE = (
    make_object(2000, shape_seed=5, sample_seed=2) @ Rotation.random(random_state=0).as_matrix().T
)


@pytest.fixture
def pair(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    np.save("target.npy", TARGET)
    np.save("source.npy", SOURCE + 0.3)
    return tmp_path


def test_a_converged_result_with_little_support_exits_untrusted(pair, monkeypatch, capfd):
    assert main(["register", "source.npy", "target.npy", "--json"]) == EXIT_OK
    trusted = json.loads(capfd.readouterr().out)
    assert trusted["trusted"] is True and trusted["trust_problems"] == []
    assert trusted["support"] >= TRUST_SUPPORT
    # The same result, had its matches barely agreed with it.
    monkeypatch.setattr(RegistrationResult, "support", property(lambda self: 0.0067))
    assert main(["register", "source.npy", "target.npy", "--json"]) == EXIT_UNTRUSTED
    out, err = capfd.readouterr()
    summary = json.loads(out)
    assert summary["converged"] is True and summary["trusted"] is False
    assert summary["support"] == 0.0067 and "little support: 0.67%" in summary["trust_problems"][0]
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("o3d-rpointhop: warning: the result is not")


def test_float32_clouds_at_survey_coordinates_exit_untrusted_in_one_line_each(pair, capfd):
    """The precision warning is a line of the command's own, not a Python warning with
    its source line; the verdict names both files."""
    np.save("target32.npy", (TARGET * 40 + SURVEY).astype(np.float32))
    np.save("source32.npy", (SOURCE * 40 + SURVEY).astype(np.float32))
    status = main(["register", "source32.npy", "target32.npy", "--json"])
    out, err = capfd.readouterr()
    assert status == EXIT_UNTRUSTED
    problems = json.loads(out)["trust_problems"]
    assert [p.split()[0] for p in problems] == ["source32.npy", "target32.npy"]
    lines = err.splitlines()
    assert all(line.startswith("o3d-rpointhop: warning: ") for line in lines), err
    assert sum("float32 coordinates" in line for line in lines) == 2
    assert "warnings.warn" not in err and ".py:" not in err


def test_transformations_keep_every_digit_and_read_back_in_every_form(pair, capfd):
    assert main(["register", "source.npy", "target.npy", "--transform", "T.txt"]) == EXIT_OK
    assert main(["register", "source.npy", "target.npy", "--transform", "T.json"]) == EXIT_OK
    assert main(["register", "source.npy", "target.npy", "--result", "R.json"]) == EXIT_OK
    capfd.readouterr()
    matrix = np.array(json.loads((pair / "T.json").read_text())["transformation"])
    np.testing.assert_array_equal(np.loadtxt(pair / "T.txt"), matrix)  # to the bit
    for written in ("T.txt", "T.json", "R.json"):
        assert main(["evaluate", "source.npy", "target.npy", "--transform", written]) == EXIT_OK
        assert main(["register", "source.npy", "target.npy", "--init", written]) == EXIT_OK
    assert "error" not in capfd.readouterr().err


def test_options_are_not_abbreviated(pair, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["register", "source.npy", "target.npy", "--voxel", "0.05"])
    assert stop.value.code == EXIT_USAGE
    assert "unrecognized arguments: --voxel" in capsys.readouterr().err


def test_bad_inputs_get_one_line_naming_the_file(tmp_path, monkeypatch, capfd):
    """Random bytes as a KITTI sweep, a folder that does not exist, a scan too small to
    describe among good ones (named as the one that coarsens the rest): one line on
    stderr each, naming the file, and no Python warning before it."""
    monkeypatch.chdir(tmp_path)
    np.save("target.npy", TARGET)
    (tmp_path / "noise.bin").write_bytes(np.random.default_rng(0).bytes(4000))
    assert main(["register", "noise.bin", "target.npy"]) == 1
    err = capfd.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("o3d-rpointhop: error: noise.bin"), err
    assert main(["reconstruct", "nofolder", "target.npy", "-o", "m.ply"]) == 1
    assert capfd.readouterr().err.splitlines() == [
        "o3d-rpointhop: error: nofolder: no such file or folder"
    ]
    folder = tmp_path / "scans"
    folder.mkdir()
    np.save(folder / "a.npy", TARGET)
    np.save(folder / "b.npy", SOURCE)
    np.save(folder / "tiny.npy", TARGET[:3])
    assert main(["reconstruct", str(folder), "-o", "m.ply"]) == 1
    (line,) = capfd.readouterr().err.splitlines()
    assert "tiny.npy (3 points) needs" in line and "scan 2" not in line


def test_a_cloud_with_more_than_three_columns_is_told_what_to_pass():
    from o3d_rpointhop import RPointHopTransformer

    model = RPointHopTransformer.pretrained("object")
    with pytest.raises(
        ValueError, match=r"has 4 feature\(s\) \(shape=\(500, 4\)\), not 3.*X\[:, :3\]"
    ) as info:
        model.transform(np.random.default_rng(0).random((500, 4)))
    assert "minimum" not in str(info.value)


def test_every_option_of_every_command_says_what_it_does():
    from o3d_rpointhop.cli import build_parser

    def silent(parser, prefix):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield from silent(sub, f"{prefix} {name}")
            if not action.help and action.dest != "help":
                yield f"{prefix} {action.option_strings or action.dest}"

    assert list(silent(build_parser(every=True), "o3d-rpointhop")) == []
