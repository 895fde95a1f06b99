"""Config files, --set and the config command: every setting reachable from the CLI."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from o3d_rpointhop import register
from o3d_rpointhop.cli import EXIT_ERROR, main
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration import RegistrationSettings

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


@pytest.fixture
def pair(tmp_path):
    target = make_object(1500, shape_seed=3, sample_seed=1)
    source = make_object(1500, shape_seed=3, sample_seed=2) + [0.2, 0.0, 0.0]
    np.save(tmp_path / "s.npy", source)
    np.save(tmp_path / "t.npy", target)
    return source, target, [str(tmp_path / "s.npy"), str(tmp_path / "t.npy")]


def _run(capsys, args) -> dict:
    main(["register", *args, "--json"])
    return json.loads(capsys.readouterr().out)


def test_the_printed_defaults_are_a_config_that_changes_nothing(tmp_path, capsys, pair):
    assert main(["config", "-o", str(tmp_path / "c.toml")]) == 0
    config = tomllib.loads((tmp_path / "c.toml").read_text())
    assert config["consensus"]["max_matches"] == 8000
    assert config["settings"]["icp_factors"] == [2.0, 0.5]
    assert {"register", "ransac", "consensus", "point_to_plane", "settings"} <= set(config)
    _, _, files = pair
    plain = _run(capsys, files)
    configured = _run(capsys, [*files, "--config", str(tmp_path / "c.toml")])
    assert configured["transformation"] == plain["transformation"]


def test_config_and_set_reach_step_parameters_and_settings(tmp_path, capsys, pair):
    source, target, files = pair
    (tmp_path / "c.toml").write_text(
        "[register]\nglobal_method = 'consensus'\n\n[consensus]\nmax_matches = 300\n\n"
        "[settings]\nicp_factors = [3.0, 1.0]\n"
    )
    out = _run(capsys, [*files, "--config", str(tmp_path / "c.toml")])
    assert out["steps"][0]["info"]["candidate_matches"] == 300
    settings = RegistrationSettings(icp_factors=(3.0, 1.0))
    from o3d_rpointhop import ConsensusGlobal

    expected = register(
        source, target, global_method=ConsensusGlobal(max_matches=300), settings=settings
    )
    np.testing.assert_allclose(out["transformation"], expected.transformation, atol=1e-9)
    # --set wins over the file, and a flag wins over both.
    out = _run(
        capsys, [*files, "--config", str(tmp_path / "c.toml"), "--set", "consensus.max_matches=200"]
    )
    assert out["steps"][0]["info"]["candidate_matches"] == 200
    out = _run(capsys, [*files, "--config", str(tmp_path / "c.toml"), "--global", "ransac"])
    assert "iterations" in out["steps"][0]["info"]  # RANSAC's, not the consensus's
    assert "hypotheses" not in out["steps"][0]["info"]


@pytest.mark.parametrize(
    "extra, message, status",
    [
        (["--set", "ransac.max_iterations=10"], "[ransac] has no parameter 'max_iterations'", 2),
        (["--set", "icp.max_iteration=10"], "unknown section [icp]", 2),
        (["--set", "max_iteration=10"], "expected section.parameter=value", 2),
        (["--set", "ransac.max_iteration=-5"], "[ransac]: The 'max_iteration' parameter", 2),
        (["--set", "ransac.max_iteration=abc"], "[ransac]: The 'max_iteration' parameter", 2),
        (["--set", "settings.icp_factors=[]"], "[settings]:", 2),
        (["--config", "missing.toml"], "no such config file", EXIT_ERROR),
    ],
)
def test_bad_settings_get_one_line(tmp_path, monkeypatch, capsys, pair, extra, message, status):
    """Settings are checked before the clouds are read: a bad one is reported even when
    the clouds do not exist; a bad value is a usage error (exit status 2)."""
    monkeypatch.chdir(tmp_path)
    _, _, files = pair
    assert main(["register", *files, *extra]) == status
    err = capsys.readouterr().err
    assert err.startswith("o3d-rpointhop: error:") and message in err
    assert main(["register", "no_such.ply", "no_such_either.ply", *extra]) == status
    assert message in capsys.readouterr().err


def test_model_object_runs_what_the_default_runs(capsys, pair):
    """``--model object`` is the default; ``--model modelnet40`` is the paper's model on
    the 128 axes registration matches."""
    import argparse

    from o3d_rpointhop.cli._common import descriptor_of

    _, _, files = pair
    default = _run(capsys, files)
    named = _run(capsys, [*files, "--model", "object"])
    assert named["transformation"] == default["transformation"]
    paper = descriptor_of(argparse.Namespace(descriptor="rpointhop", model="modelnet40"))
    assert paper.n_features_out_ == 128 and len(paper.n_neighbors) == 4
    assert descriptor_of(argparse.Namespace(descriptor="rpointhop", model=None)) is None
