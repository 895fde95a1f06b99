"""The benchmark method registry."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop import (
    RPointHopTransformer,
)
from o3d_rpointhop.evaluation.methods import METHODS, check_methods, default_methods
from o3d_rpointhop.evaluation.metrics import (
    pair_errors,
)
from o3d_rpointhop.evaluation.peers import kiss_matcher_available
from o3d_rpointhop.evaluation.protocols import make_pairs
from o3d_rpointhop.evaluation.runner import run_method


def test_scene_only_methods_are_refused_on_objects():
    assert METHODS["rpointhop-loso"].datasets == {"3dmatch"}
    for objects in ("modelnet40", "bunny"):
        assert not {"rpointhop-loso", "rpointhop-scene"} & set(default_methods(objects))
        with pytest.raises(ValueError, match=r"do not apply to .* \(only to 3dmatch\)"):
            check_methods(["icp", "rpointhop-loso"], objects)
    assert {"rpointhop-scene", "rpointhop-loso", "fpfh-ransac-icp-5cm"} <= set(
        default_methods("3dmatch")
    )
    assert check_methods(["rpointhop-loso"], "3dmatch") == ["rpointhop-loso"]
    with pytest.raises(ValueError, match="unknown methods"):
        check_methods(["magic"], "3dmatch")


def test_default_method_sets_are_the_committed_ones():
    """The committed result files hold these methods, in this order."""
    objects = [
        "rpointhop-svd",
        "rpointhop-svd-icp",
        "rpointhop-ransac",
        "rpointhop-ransac-icp",
        "rpointhop-consensus-icp",
        "rpointhop-ransac-icp-sym",
        "fpfh-ransac",
        "fpfh-fgr",
        "fpfh-ransac-icp",
        "fpfh-pipeline-ransac-icp",
        "fpfh-pipeline-consensus-icp",
        "rpointhop-open3d-ransac-icp",
        "icp",
    ]
    assert default_methods("modelnet40") == default_methods("bunny") == objects


#: Methods that report no flag on their result.
NO_CLAIMS = {
    "fpfh-ransac",
    "fpfh-fgr",
    "fpfh-ransac-icp",
    "fpfh-ransac-icp-5cm",
    "rpointhop-open3d-ransac-icp",
    "icp",
}


@pytest.mark.slow
def test_every_method_runs(shapes):

    model = RPointHopTransformer().fit(list(shapes[:, :1024]))
    (pair,) = make_pairs(shapes[:1], "paper", seed=0)
    for name in METHODS:
        if name == "kiss-matcher" and not kiss_matcher_available():
            # the optional peer: without its wheel the method refuses with the install line
            with pytest.raises(ValueError, match=r"pip install '\.\[peers\]'"):
                run_method(name, pair.source, pair.target, descriptor=model, voxel=0.05)
            continue
        run = run_method(name, pair.source, pair.target, descriptor=model, voxel=0.05)
        estimate, rotation = run.transformation, run.transformation[:3, :3]
        assert estimate.shape == (4, 4) and np.isfinite(run.seconds)
        # register()'s methods and KISS-Matcher vouch for their results; the others cannot
        assert (run.claimed is None) == (name in NO_CLAIMS), name
        np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-9)  # rigid
        assert np.linalg.det(rotation) == pytest.approx(1.0) and estimate[3].tolist() == [
            0,
            0,
            0,
            1,
        ]
        if name != "icp":  # a moved copy: every global method must find it
            assert pair_errors(estimate, pair.truth)["rotation_error_deg"] < 2.0, name
    with pytest.raises(ValueError, match="unknown method"):
        run_method("magic", pair.source, pair.target, descriptor=model, voxel=0.05)


def test_a_method_whose_peer_is_missing_is_skipped_with_its_install_line(monkeypatch, capsys):
    """Each method says whether it is available and what to install: a benchmark skips
    it with that line, a direct run refuses it; a scene method reads its own model."""
    import dataclasses

    from o3d_rpointhop.evaluation import methods as registry

    missing = dataclasses.replace(registry.METHODS["kiss-matcher"], available=lambda: False)
    monkeypatch.setitem(registry.METHODS, "kiss-matcher", missing)
    assert check_methods(["kiss-matcher", "fpfh-pipeline-consensus-icp"], "3dmatch") == [
        "fpfh-pipeline-consensus-icp"
    ]
    assert "kiss-matcher skipped: not installed (pip install '.[peers]'" in capsys.readouterr().err
    cloud = np.zeros((10, 3))
    with pytest.raises(ValueError, match=r"kiss-matcher is not installed: pip install"):
        run_method("kiss-matcher", cloud, cloud, descriptor=None, voxel=0.05)
    from o3d_rpointhop.descriptors import content_hash

    scene = registry.METHODS["rpointhop-scene"].preload(None)
    assert content_hash(scene) == content_hash(RPointHopTransformer.pretrained("scene"))
    assert registry.METHODS["icp"].preload("given") == "given"


def test_a_methods_global_step_is_data_cloned_for_each_pair(monkeypatch):
    """The table holds a method's global step as an estimator with its parameters; each
    pair registers with a clone of it (the same parameters, never the table's object)."""
    from o3d_rpointhop import ConsensusGlobal
    from o3d_rpointhop.evaluation import methods as registry

    table_step = registry.METHODS["rpointhop-scene-matches-2000"].run.options["global_method"]
    assert isinstance(table_step, ConsensusGlobal)
    assert table_step.n_hypotheses == 1 and table_step.matcher.max_matches == 2000
    used = []
    monkeypatch.setattr(registry, "register", lambda *a, **kw: used.append(kw["global_method"]))
    run = registry.METHODS["rpointhop-scene-matches-2000"].run
    cloud = np.zeros((10, 3))
    run(cloud, cloud, None, 0.05, 0, None)
    run(cloud, cloud, None, 0.05, 0, None)
    assert used[0] is not table_step and used[1] is not used[0]
    assert used[0].n_hypotheses == used[1].n_hypotheses == 1
    assert used[0].matcher is not table_step.matcher
    assert used[0].matcher.get_params() == table_step.matcher.get_params()
