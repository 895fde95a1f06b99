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


def _assert_config_repeats(capsys, tmp_path, files, out, line):
    """``config --from`` a run's JSON writes a config holding ``line`` that gives the
    run's transformation again."""
    (tmp_path / "out.json").write_text(json.dumps(out))
    assert (
        main(["config", "--from", str(tmp_path / "out.json"), "-o", str(tmp_path / "c.toml")]) == 0
    )
    assert line in (tmp_path / "c.toml").read_text()
    again = _run(capsys, [*files, "--config", str(tmp_path / "c.toml")])
    assert again["transformation"] == out["transformation"]


def test_the_printed_defaults_are_a_config_that_changes_nothing(tmp_path, capsys, pair):
    assert main(["config", "-o", str(tmp_path / "c.toml")]) == 0
    config = tomllib.loads((tmp_path / "c.toml").read_text())
    assert config["consensus"]["matcher"]["max_matches"] == 4000
    assert config["settings"]["icp_factors"] == [2.0, 0.5]
    assert {"register", "ransac", "consensus", "point_to_plane", "settings"} <= set(config)
    _, _, files = pair
    plain = _run(capsys, files)
    configured = _run(capsys, [*files, "--config", str(tmp_path / "c.toml")])
    assert configured["transformation"] == plain["transformation"]


def test_config_and_set_reach_step_parameters_and_settings(tmp_path, capsys, pair):
    source, target, files = pair
    (tmp_path / "c.toml").write_text(
        "[register]\nglobal_method = 'consensus'\n\n[consensus.matcher]\nmax_matches = 300\n\n"
        "[settings]\nicp_factors = [3.0, 1.0]\n"
    )
    out = _run(capsys, [*files, "--config", str(tmp_path / "c.toml")])
    assert out["steps"][0]["info"]["candidate_matches"] == 300
    settings = RegistrationSettings(icp_factors=(3.0, 1.0))
    from o3d_rpointhop import ConsensusGlobal, Matcher

    matcher = Matcher(both_directions=True, max_matches=300)
    expected = register(
        source, target, global_method=ConsensusGlobal(matcher=matcher), settings=settings
    )
    np.testing.assert_allclose(out["transformation"], expected.transformation, atol=1e-9)
    # --set wins over the file, and a flag wins over both.
    out = _run(
        capsys,
        [
            *files,
            "--config",
            str(tmp_path / "c.toml"),
            "--set",
            "consensus.matcher.max_matches=200",
        ],
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
        (
            ["--global", "consensus", "--set", "consensus.matcher.metric=manhattan"],
            "[consensus]: The 'metric' parameter",
            2,
        ),
        (  # a section the run does not use is checked too
            ["--global", "ransac", "--set", "consensus.matcher.metric=manhattan"],
            "[consensus] (not used by this run): The 'metric' parameter",
            2,
        ),
        (
            [
                "--set",
                "consensus.matcher.frame_turns=4",
                "--set",
                "consensus.matcher.mutual_filter=true",
            ],
            "[consensus] (not used by this run): Matcher: frame_turns=4 cannot",
            2,
        ),
        (  # a check that relates two parameters: also before any cloud is read
            [
                "--global",
                "consensus",
                "--set",
                "consensus.matcher.n_nearest=2",
                "--set",
                "consensus.matcher.mutual_filter=true",
            ],
            "[consensus]: Matcher: n_nearest=2 cannot be combined",
            2,
        ),  # fmt: skip
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
    """``--model object`` is the default; ``--model X`` is what ``pretrained("X")`` gives,
    registering or describing (``--n-components`` its axes)."""
    from o3d_rpointhop.cli._descriptor import descriptor_from

    _, _, files = pair
    default = _run(capsys, files)
    named = _run(capsys, [*files, "--model", "object"])
    assert named["transformation"] == default["transformation"]
    paper, section = descriptor_from({}, "rpointhop", "modelnet40")
    assert paper.n_features_out_ == 1624 and len(paper.n_neighbors) == 4
    assert section["n_components"] is None
    for registering in (True, False):
        axes, _ = descriptor_from({}, "rpointhop", "modelnet40", 128, registering=registering)
        assert axes.n_features_out_ == 128
    assert descriptor_from({}, None, None) == (
        None,
        {**section, "model": None, "n_components": None},
    )


def test_outputs_record_their_run_and_config_from_repeats_it(tmp_path, capsys, pair):
    """A JSON output names the library, the commit, the descriptor (shipped name and
    content hash) and the whole config; ``config --from`` turns it into a file that,
    given back, repeats the run to the bit, and a file without a record is refused."""
    from o3d_rpointhop import RPointHopTransformer
    from o3d_rpointhop.descriptors import content_hash

    _, _, files = pair
    changed = [
        "--set", "consensus.matcher.max_matches=3000", "--set", "settings.icp_factors=[3.0, 1.0]",
        "--seed", "4", "--model", "scene", "--result", str(tmp_path / "r.json"),
    ]  # fmt: skip
    out = _run(capsys, [*files, *changed])
    record = out["provenance"]
    assert record["o3d_rpointhop"] and "commit" in record and record["command"] == "register"
    assert record["descriptor"]["model"] == "scene"
    assert record["descriptor"]["sha256"] == content_hash(RPointHopTransformer.pretrained("scene"))
    config = record["config"]
    assert config["register"]["random_state"] == 4 and config["descriptor"]["model"] == "scene"
    # The scene model states the consensus; every step is named with every parameter.
    assert config["register"]["global_method"] == "consensus"
    assert config["settings"]["icp_factors"] == [3.0, 1.0]
    assert (
        config["consensus.matcher"]["max_matches"] == 3000
        and "max_iteration" in config["point_to_plane"]
    )
    saved = json.loads((tmp_path / "r.json").read_text())
    assert saved["provenance"] == record
    for source in ("r.json", "out.json"):
        (tmp_path / "out.json").write_text(json.dumps(out))
        assert (
            main(["config", "--from", str(tmp_path / source), "-o", str(tmp_path / "c.toml")]) == 0
        )
        again = _run(capsys, [*files, "--config", str(tmp_path / "c.toml")])
        assert again["transformation"] == out["transformation"]
        assert again["provenance"]["config"] == config
        (tmp_path / "c.toml").unlink()
    (tmp_path / "plain.json").write_text("{}")
    assert main(["config", "--from", str(tmp_path / "plain.json")]) == EXIT_ERROR
    assert "records no run" in capsys.readouterr().err


def test_describe_and_fit_take_a_config_and_record_their_runs(tmp_path, capsys):
    """fit: [fit] reaches the estimator (flags win over it), the model's record beside
    it repeats the fit through ``config --from``; describe: [descriptor] and [fpfh]
    choose and configure the descriptor, and the record names it."""
    from o3d_rpointhop import FPFHTransformer, RPointHopTransformer
    from o3d_rpointhop.io import read_cloud

    clouds = []
    for k in range(2):
        np.save(tmp_path / f"c{k}.npy", make_object(300, shape_seed=k))
        clouds.append(str(tmp_path / f"c{k}.npy"))
    model = tmp_path / "m.npz"
    sets = ["--set", "fit.n_neighbors=[24, 16]", "--set", "fit.hop_sizes=[1.0, 0.5]"]
    args = [*clouds, "-o", str(model), "--random-state", "3", "--set", "fit.lrf_neighbors=20"]
    assert main(["fit", *args, *sets]) == 0
    fitted = RPointHopTransformer.load(model)
    assert fitted.n_neighbors == (24, 16) and fitted.lrf_neighbors == 20
    assert fitted.random_state == 3
    record = json.loads((tmp_path / "m.npz.json").read_text())["provenance"]
    assert record["command"] == "fit" and record["config"]["fit"]["n_neighbors"] == [24, 16]
    toml = tmp_path / "fit.toml"
    assert main(["config", "--from", str(tmp_path / "m.npz.json"), "-o", str(toml)]) == 0
    again = tmp_path / "again.npz"
    assert main(["fit", *clouds, "-o", str(again), "--config", str(toml)]) == 0
    np.testing.assert_array_equal(
        RPointHopTransformer.load(again).transform(np.load(clouds[0])),
        fitted.transform(np.load(clouds[0])),
    )
    assert main(["fit", *clouds, "-o", str(tmp_path / "x.npz"), "--set", "fit.pooling='x'"]) == 2
    assert "[fit]" in capsys.readouterr().err

    out = tmp_path / "d.npy"
    sets = ["--set", "descriptor.kind='fpfh'", "--set", "fpfh.max_nn=40"]
    assert main(["describe", clouds[0], "-o", str(out), *sets]) == 0
    expected = FPFHTransformer(max_nn=40).transform(read_cloud(clouds[0]))
    np.testing.assert_array_equal(np.load(out), expected)
    record = json.loads((tmp_path / "d.npy.json").read_text())["provenance"]
    assert record["descriptor"]["params"]["max_nn"] == 40
    assert main(["describe", clouds[0], "-o", str(out), "--model", str(model)]) == 0
    record = json.loads((tmp_path / "d.npy.json").read_text())["provenance"]
    assert record["descriptor"]["model"] == "fitted"


def test_with_fpfh_runs_the_pooled_hypotheses_and_a_config_repeats_it(tmp_path, capsys, pair):
    """``--with-fpfh`` gives register() the consensus with FPFH's matches beside the
    model's (the library's ``PooledMatcher.with_fpfh``): the same estimate as the
    library's; the record says ``with_fpfh`` and its config repeats the run; a step that
    is not the consensus, or a value that is not a bool, is refused by name."""
    from o3d_rpointhop import ConsensusGlobal, PooledMatcher
    from o3d_rpointhop.cli import EXIT_USAGE

    source, target, files = pair
    out = _run(capsys, [*files, "--model", "scene", "--with-fpfh", "--viewpoints", "none"])
    (step,) = [s for s in out["steps"] if s["name"] == "global"]
    assert set(step["info"]["hypothesis_parts"]) <= {"model", "fpfh"}
    assert step["info"]["hypothesis_parts"]  # only the pooled step names parts
    config = out["provenance"]["config"]
    assert config["register"]["with_fpfh"] is True
    assert config["consensus.matcher"]["max_matches"] == 4000
    library = register(
        source,
        target,
        "scene",
        global_method=ConsensusGlobal(matcher=PooledMatcher.with_fpfh()),
        viewpoints=None,
    )
    np.testing.assert_allclose(out["transformation"], library.transformation, atol=1e-12)
    _assert_config_repeats(capsys, tmp_path, files, out, "with_fpfh = true")
    plain = _run(
        capsys, [*files, "--model", "scene", "--viewpoints", "none", "--with-fpfh", "never"]
    )
    assert plain["provenance"]["config"]["register"]["with_fpfh"] is False
    assert "hypothesis_parts" not in [s for s in plain["steps"] if s["name"] == "global"][0]["info"]
    for extra, message in (
        (["--model", "scene", "--global", "ransac", "--with-fpfh"], "got ransac"),
        (["--model", "scene", "--set", "register.with_fpfh=1"], "true, false"),
        (["--descriptor", "fpfh", "--global", "consensus", "--with-fpfh"], "has it"),
    ):
        assert main(["register", *files, *extra]) == EXIT_USAGE
        assert message in capsys.readouterr().err


def test_the_scene_path_asks_fpfh_as_a_fallback(tmp_path, capsys, pair):
    """With the scene model (here with the sensors known), the command line's default
    global step is register()'s: the consensus with FPFH's as a fallback (``with_fpfh`` recorded as
    ``"fallback"``, and a config repeats it); ``--with-fpfh never`` is the model's
    consensus alone, as ``global_method="consensus"`` gives it."""
    source, target, files = pair
    scene = ["--model", "scene", "--viewpoints", "origin"]
    out = _run(capsys, [*files, *scene])
    (step,) = [s for s in out["steps"] if s["name"] == "global"]
    assert step["info"]["fallback"] in (True, False)
    assert out["provenance"]["config"]["register"]["with_fpfh"] == "fallback"
    library = register(source, target, "scene", viewpoints="origin")
    np.testing.assert_allclose(out["transformation"], library.transformation, atol=1e-12)
    _assert_config_repeats(capsys, tmp_path, files, out, 'with_fpfh = "fallback"')

    alone = _run(capsys, [*files, *scene, "--with-fpfh", "never"])
    assert alone["provenance"]["config"]["register"]["with_fpfh"] is False
    (step,) = [s for s in alone["steps"] if s["name"] == "global"]
    assert "fallback" not in step["info"]
    library = register(source, target, "scene", viewpoints="origin", global_method="consensus")
    np.testing.assert_allclose(alone["transformation"], library.transformation, atol=1e-12)


def test_the_summary_says_when_fpfh_was_asked(tmp_path, capsys):
    """A room scan against noise: the scene model's estimate explains almost none of its
    matches, so FPFH's consensus is asked, and the printed summary says so (not for a
    pair the model alone serves)."""
    from o3d_rpointhop.datasets import make_room

    room = make_room(4000, random_state=1) + [0.0, 0.0, 2.5]
    noise = np.random.default_rng(0).uniform(-1, 1, size=(4000, 3)) + [0.0, 0.0, 3.0]
    twin = make_room(4000, random_state=2)[::-1] * [1, -1, 1] + [0.0, 0.0, 2.5]
    for name, cloud in (("room", room), ("noise", noise), ("twin", twin)):
        np.save(tmp_path / f"{name}.npy", cloud)
    scene = ["--model", "scene", "--viewpoints", "origin"]
    main(["register", str(tmp_path / "noise.npy"), str(tmp_path / "room.npy"), *scene])
    assert "FPFH's consensus was asked too" in capsys.readouterr().out
    main(["register", str(tmp_path / "twin.npy"), str(tmp_path / "room.npy"), *scene])
    assert "FPFH's consensus was asked" not in capsys.readouterr().out
