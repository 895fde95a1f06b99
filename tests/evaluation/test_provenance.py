"""Benchmark records name what produced them, and a record that does not is refused."""

import copy
import json

import pytest

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.descriptors import content_hash
from o3d_rpointhop.evaluation.methods import METHODS
from o3d_rpointhop.evaluation.provenance import (
    REQUIRED,
    check_provenance,
    model_identity,
    read_results,
    run_provenance,
)
from o3d_rpointhop.evaluation.report import markdown


def test_content_hash_follows_the_model_not_the_file(fitted, tmp_path):
    path = tmp_path / "model.npz"
    fitted.save(path)
    assert content_hash(RPointHopTransformer.load(path)) == content_hash(fitted)
    changed = copy.deepcopy(fitted)
    changed.kernels_[0] = changed.kernels_[0].copy()
    changed.kernels_[0][0, 0, 0] += 1e-3
    assert content_hash(changed) != content_hash(fitted)
    full = RPointHopTransformer.pretrained("modelnet40", n_components=None)
    axes = RPointHopTransformer.pretrained("modelnet40", n_components=32)
    assert content_hash(full) != content_hash(axes)
    assert len(content_hash(full)) == 64 and int(content_hash(full), 16) >= 0


def test_identity_names_the_shipped_models_and_a_fitted_one(fitted):
    scene = model_identity(RPointHopTransformer.pretrained("scene"))
    assert scene["model"] == "scene" and scene["n_features_out"] == 96
    assert scene["training_scenes"]  # the scenes it saw
    assert model_identity(RPointHopTransformer.pretrained("modelnet40"))["model"] == "modelnet40"
    assert model_identity(fitted)["model"] == "fitted"
    assert model_identity(fitted)["sha256"] == content_hash(fitted)


def test_every_method_names_its_descriptor(fitted):
    provenance = run_provenance(list(METHODS), fitted, loso={"scene-a": fitted})
    assert set(REQUIRED) <= set(provenance)
    json.dumps(provenance)  # JSON-ready
    methods = provenance["methods"]
    assert set(methods) == set(METHODS)
    scene = RPointHopTransformer.pretrained("scene")
    # The scene methods name the scene model, not the benchmark's own.
    assert methods["rpointhop-scene"]["descriptor"]["sha256"] == content_hash(scene)
    assert methods["rpointhop-ransac-icp"]["descriptor"]["sha256"] == content_hash(fitted)
    recipe = methods["rpointhop-open3d-ransac-icp"]["descriptor"]
    assert recipe["model"] == "object" and recipe["n_features_out"] == 24
    assert methods["rpointhop-loso"]["descriptor"]["per_scene"]["scene-a"]["model"] == "fitted"
    assert methods["fpfh-pipeline-consensus-icp"]["descriptor"]["class"].endswith("FPFHTransformer")
    assert methods["fpfh-ransac-icp"]["descriptor"]["class"].startswith("open3d.")
    assert methods["rpointhop-svd"]["options"] == {"global_method": "svd", "refine": None}
    # A global step is named by its parameters, as scikit-learn prints them.
    assert methods["rpointhop-scene-matches-2000"]["options"] == {
        "global_method": "ConsensusGlobal(matcher=Matcher(both_directions=True, "
        "max_matches=2000), n_hypotheses=1)"
    }
    pooled = methods["rpointhop-scene-pooled-4000-1000-nn50"]["options"]["global_method"]
    assert "PooledMatcher" in pooled and "FPFHTransformer(max_nn=50)" in pooled
    # A union names both parts and the weight, not the benchmark's model alone.
    union = methods["rpointhop-scene-fpfh-turns"]["descriptor"]
    assert union["class"] == "o3d_rpointhop.DescriptorUnion"
    assert union["parts"]["rpointhop"]["sha256"] == content_hash(scene)
    assert union["parts"]["fpfh"]["class"] == "o3d_rpointhop.FPFHTransformer"
    assert union["transformer_weights"] == {"fpfh": 0.7}


def _result(provenance):
    out = {
        "dataset": "bunny",
        "settings": {"seed": 0, "python": "3", "open3d": "0", "numpy": "0"},
        "protocols": {"scans": {"summary": {}, "records": {"rpointhop-svd": []}}},
    }
    if provenance is not None:
        out["provenance"] = provenance
    return out


def test_a_record_without_provenance_is_refused(fitted, tmp_path):
    good = run_provenance(["rpointhop-svd"], fitted)
    check_provenance(_result(good))
    with pytest.raises(ValueError, match="no provenance"):
        check_provenance(_result(None))
    lacking = {k: v for k, v in good.items() if k != "commit"}
    with pytest.raises(ValueError, match="lacks"):
        check_provenance(_result(lacking))
    other = run_provenance(["fpfh-ransac"], fitted)
    with pytest.raises(ValueError, match="rpointhop-svd"):
        check_provenance(_result(other))
    path = tmp_path / "old.json"
    path.write_text(json.dumps(_result(None)))
    with pytest.raises(ValueError, match="old.json"):
        read_results(path)
    path.write_text(json.dumps(_result(good)))
    assert read_results(path)["provenance"]["methods"]["rpointhop-svd"]


def test_the_report_names_each_method_model(fitted):
    results = _result(run_provenance(["rpointhop-scene", "rpointhop-svd"], fitted))
    text = markdown(results)
    scene = content_hash(RPointHopTransformer.pretrained("scene"))[:12]
    assert (
        "| rpointhop-scene | o3d_rpointhop.RPointHopTransformer, model scene "
        f"(96-D, sha256 {scene})" in text
    )
    assert f"model fitted ({fitted.n_features_out_}-D, sha256 {content_hash(fitted)[:12]})" in text


#: Committed result files written before runs recorded their provenance, and the
#: script outputs that do not record it yet; each is refused by read_results until it
#: is regenerated (docs/benchmarks.md). No file may join this list.
WITHOUT_PROVENANCE: frozenset[str] = frozenset()


def test_committed_results_name_what_produced_them():
    from pathlib import Path

    folder = Path(__file__).resolve().parents[2] / "benchmarks" / "results"
    results = [p for p in sorted(folder.glob("*.json")) if not p.name.endswith("_timings.json")]
    assert results
    for path in results:
        if path.name in WITHOUT_PROVENANCE:
            with pytest.raises(ValueError, match="no provenance"):
                read_results(path)
        else:
            assert read_results(path)["provenance"]["commit"]["id"], path.name
