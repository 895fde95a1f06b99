"""The command line on bad input: one line on stderr, exit statuses, help."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import OBJECT, OTHER_SAMPLE, TURN, moved_pair_files

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.cli import EXIT_ERROR, EXIT_OK, EXIT_UNRELIABLE, main
from o3d_rpointhop.datasets import make_object

_NAN = OBJECT.copy()


_NAN[[3, 7]] = np.nan


# ------------------------------------------------------------------ the command line
@pytest.fixture
def files(tmp_path):
    np.save(tmp_path / "obj.npy", OBJECT)
    np.save(tmp_path / "other.npy", OTHER_SAMPLE @ TURN.T)
    np.save(tmp_path / "nan.npy", _NAN)
    np.save(tmp_path / "tiny.npy", OBJECT[:3])
    np.save(tmp_path / "unrelated.npy", make_object(1024, shape_seed=30, sample_seed=1))
    (tmp_path / "empty.ply").write_bytes(b"")
    (tmp_path / "adir").mkdir()
    header = "ply\nformat ascii 1.0\nelement vertex 10\n"
    header += "property float x\nproperty float y\nproperty float z\nend_header\n"
    (tmp_path / "truncated.ply").write_text(header + "0 0 0\n1 1")
    return tmp_path


CLI_CASES = [
    (["register", "adir", "obj.npy"], EXIT_ERROR, "adir: is a directory"),
    (["register", "missing.ply", "obj.npy"], EXIT_ERROR, "missing.ply: no such file"),
    (["register", "empty.ply", "obj.npy"], EXIT_ERROR, "empty.ply: the file is empty"),
    (["register", "obj.npy", "truncated.ply"], EXIT_ERROR, "truncated.ply: damaged or unreadable"),
    (["register", "obj.npy", "nan.npy"], EXIT_ERROR, "nan.npy has 2 point(s) with NaN"),
    (["register", "obj.npy", "tiny.npy"], EXIT_ERROR, "target: tiny.npy"),
    (["register", "unrelated.npy", "obj.npy"], EXIT_UNRELIABLE, "did not converge"),
    (["describe", "obj.npy", "-o", "adir"], EXIT_ERROR, "adir: is a directory"),
    (["describe", "obj.npy", "-o", "nofolder/d.npy"], EXIT_ERROR, "does not exist"),
]


# ----------------------------------------------------------------------------- register


@pytest.mark.parametrize(("args", "status", "message"), CLI_CASES, ids=lambda v: str(v)[:40])
def test_cli_bad_input_one_line_and_status(files, monkeypatch, capfd, args, status, message):
    monkeypatch.chdir(files)
    assert main(args) == status
    out, err = capfd.readouterr()
    lines = [line for line in err.splitlines() if line]
    assert len(lines) == 1 and message in lines[0], err
    assert "\x1b[" not in out + err and "Traceback" not in err and "RPly" not in out


def test_cli_output_paths_are_exact_and_large_outputs_need_force(files, monkeypatch, capsys):
    monkeypatch.chdir(files)
    assert main(["describe", "obj.npy", "-o", "dchin", "--n-components", "8"]) == EXIT_OK
    assert (files / "dchin").is_file() and not (files / "dchin.npy").exists()
    assert np.load(files / "dchin").shape == (1024, 8)
    assert "written to dchin" in capsys.readouterr().out
    import o3d_rpointhop.cli._common as common

    monkeypatch.setattr(common, "MAX_OUTPUT_BYTES", 1000)
    assert main(["describe", "obj.npy", "-o", "big.npy"]) == EXIT_ERROR
    assert "--force" in capsys.readouterr().err and not (files / "big.npy").exists()
    assert main(["describe", "obj.npy", "-o", "big.npy", "--force"]) == EXIT_OK
    # The aligned cloud of register is held to the same limit.
    capsys.readouterr()
    assert main(["register", "obj.npy", "obj.npy", "-o", "aligned.ply"]) == EXIT_ERROR
    assert "--force" in capsys.readouterr().err and not (files / "aligned.ply").exists()
    assert main(["register", "obj.npy", "obj.npy", "-o", "aligned.ply", "--force"]) == EXIT_OK
    assert main(["fit", "obj.npy", "other.npy", "-o", "model"]) == EXIT_OK
    assert (files / "model").is_file() and not (files / "model.npz").exists()
    RPointHopTransformer.load(files / "model")


def test_cli_help_lists_the_exit_statuses(capsys):
    for args in (["--help"], ["register", "--help"]):
        with pytest.raises(SystemExit):
            main(args)
        text = capsys.readouterr().out
        assert "exit status:" in text and "3  register/demo finished" in text


@pytest.mark.parametrize(
    "args, message",
    [
        (["describe", "missing.ply", "--model", "m.npz", "-o", "d.npy"], "no such model file"),
        (["describe", "missing.ply", "-o", "d.npy"], "no such file"),
        (
            ["fit", "bad.ply", "-o", "m.npz"],
            "bad.ply: damaged or unreadable .ply file (not a PLY file",
        ),
        (["fit", "cloud.foo", "-o", "m.npz"], "unknown point cloud format"),
        (["fit", "small.npy", "-o", "m.npz"], "too few"),
    ],
)
def test_bad_input_exits_nonzero_with_a_message(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.ply").write_text("not a ply file")
    (tmp_path / "cloud.foo").write_text("1 2 3")
    np.save(tmp_path / "small.npy", make_object(20))
    assert main(args) == 1
    err = capsys.readouterr().err
    assert err.startswith("o3d-rpointhop: error:") and message in err


def test_usage_errors_exit_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["fit"])
    assert exc.value.code == 2


@pytest.mark.parametrize(
    "extra, message, status",
    [
        (["--descriptor", "fpfh", "--model", "m.npz"], "--model applies to the rpointhop", 1),
        (["--set", "descriptor.fpfh_weight=0.5"], "fpfh_weight applies to the rpointhop+fpfh", 2),
        (
            ["--descriptor", "rpointhop+fpfh", "--set", "descriptor.fpfh_weight=0"],
            "must be positive and finite",
            2,
        ),
        (["--init", "bad.txt"], "3 numbers, expected 4", 1),
        (["--model", "missing.npz"], "no such model file", 1),
        (["--refine", "none", "--symmetry-check"], "--symmetry-check needs an ICP", 2),
    ],
)
def test_register_errors(tmp_path, monkeypatch, capsys, extra, message, status):
    src, tgt, _ = moved_pair_files(tmp_path)
    monkeypatch.chdir(tmp_path)
    np.savetxt(tmp_path / "bad.txt", np.eye(3))
    assert main(["register", src, tgt, *extra]) == status
    assert message in capsys.readouterr().err


def test_register_usage_errors():
    for args in (
        ["register", "a.ply"],
        ["register", "a", "b", "--voxel-size", "-1"],
        ["register", "a", "b", "--global", "teaser"],
        ["register", "a", "b", "--n-global-points", "2"],
        ["register", "a", "b", "--n-global-points", "many"],
    ):
        with pytest.raises(SystemExit) as exc:
            main(args)
        assert exc.value.code == 2


def test_debug_shows_the_traceback_where_an_unexpected_error_says_how(
    tmp_path, monkeypatch, capsys
):
    import o3d_rpointhop.cli.describe as describe

    def broken(*args, **kwargs):
        raise RuntimeError("something broke")

    monkeypatch.setattr(describe, "descriptor_from", broken)
    np.save(tmp_path / "c.npy", OBJECT)
    args = ["describe", str(tmp_path / "c.npy"), "-o", str(tmp_path / "d.npy")]
    assert main(args) == EXIT_ERROR
    err = capsys.readouterr().err
    assert "unexpected RuntimeError: something broke" in err
    assert "'o3d-rpointhop --debug ...' shows where" in err and "Traceback" not in err
    with pytest.raises(RuntimeError, match="something broke"):
        main(["--debug", *args])


def test_verbose_says_what_is_done_and_quiet_says_only_errors(tmp_path, capsys):
    """-v logs each file read and the registration's outcome, -vv each step; -q drops
    the flagged result's warning while the exit status still says it."""
    np.save(tmp_path / "s.npy", OBJECT)
    np.save(tmp_path / "far.npy", OBJECT + [50.0, 0.0, 0.0])
    pair = [str(tmp_path / "s.npy"), str(tmp_path / "s.npy")]
    assert main(["-v", "register", *pair]) == 0
    err = capsys.readouterr().err
    assert f"o3d-rpointhop: info: read {pair[0]}: {len(OBJECT)} points" in err
    assert "o3d-rpointhop: info: registered at resolution" in err and "step " not in err
    assert main(["-vv", "register", *pair]) == 0
    assert "o3d-rpointhop: debug: step global: fitness" in capsys.readouterr().err
    assert main(["register", *pair]) == 0
    assert capsys.readouterr().err == ""
    # The source 50 units away and ICP alone: nothing overlaps, flagged.
    bad = [str(tmp_path / "far.npy"), pair[1], "--global", "none"]
    assert main(["register", *bad]) == 3
    assert "o3d-rpointhop: warning: the result did not converge" in capsys.readouterr().err
    assert main(["-q", "register", *bad]) == 3
    assert capsys.readouterr().err == ""
    # After the command, as people type them, the same.
    assert main(["register", *bad, "-q"]) == 3
    assert capsys.readouterr().err == ""
    assert main(["register", *pair, "-vv"]) == 0
    assert "o3d-rpointhop: debug: step global: fitness" in capsys.readouterr().err
    with pytest.raises(FileNotFoundError):  # --debug after the command: the traceback
        main(["register", pair[0], str(tmp_path / "missing.npy"), "--debug"])
