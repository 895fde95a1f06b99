"""Real-world inputs: any array a numpy or Open3D user hands over, clouds anywhere in
space, degenerate geometry, and the command line's errors and exit statuses."""

from __future__ import annotations

import warnings

import numpy as np
import open3d as o3d
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from o3d_rpointhop import FPFHTransformer, RegistrationWarning, RPointHopTransformer, register
from o3d_rpointhop.cli import EXIT_ERROR, EXIT_OK, EXIT_UNRELIABLE, main
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg

OBJECT = make_object(1024, shape_seed=3, sample_seed=1)
OTHER_SAMPLE = make_object(1024, shape_seed=3, sample_seed=2)
TURN = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z


@pytest.fixture(scope="module")
def model():
    return RPointHopTransformer.pretrained(n_components=32)


def _pose(rotation, shift):
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation, shift
    return out


# ------------------------------------------------------------------ anywhere in space
@pytest.mark.parametrize(
    ("global_method", "refine"),
    [
        ("ransac", "point_to_plane"),
        ("ransac", "point_to_point"),
        ("ransac", "generalized"),
        ("ransac", "multiscale"),
        ("fgr", "point_to_plane"),
        ("fgr", "generalized"),
        ("svd", "point_to_plane"),
        ("svd", "point_to_point"),
    ],
)
def test_same_errors_at_any_offset(model, global_method, refine):
    """Every global method and ICP variant: the same result within 0.1 mm (in units of
    a 1 m object) at offsets 0, 1e3, 1e6 and survey-like coordinates."""
    source = OTHER_SAMPLE @ TURN.T
    truth = _pose(TURN.T, np.zeros(3))
    errors = []
    for offset in ([0, 0, 0], [1e3, -1e3, 1e3], [1e6, 1e6, 1e6], [512345.0, 4123456.0, 87.0]):
        shift = np.asarray(offset, dtype=np.float64)
        moved = _pose(np.eye(3), shift) @ truth @ _pose(np.eye(3), -shift)
        result = register(
            source + shift, OBJECT + shift, model, global_method=global_method, refine=refine
        )
        # Mean distance between where the source lands and where it should.
        gap = apply_transform(source + shift, result.transformation) - apply_transform(
            source + shift, moved
        )
        errors.append(np.linalg.norm(gap, axis=1).mean())
        if global_method != "svd":  # the paper's one-shot fit fails on resampled pairs
            assert rotation_error_deg(result.transformation, moved) < 5.0
    assert max(errors) - min(errors) < 1e-4


def test_float32_at_survey_scale_warns_about_precision(model):
    far = (OBJECT * 10 + [512345.0, 4123456.0, 87.0]).astype(np.float32)
    with pytest.warns(RegistrationWarning, match="float32 resolves only"):
        register(far, far, model)


# ------------------------------------------------------------------ any array
def _forms(points):
    """Every form a user may hand over, with a description."""
    readonly = points.copy()
    readonly.flags.writeable = False
    tensor = o3d.t.geometry.PointCloud(o3d.core.Tensor(points.astype(np.float32)))
    return {
        "read-only": readonly,
        "non-contiguous": np.repeat(points, 2, axis=0)[::2],
        "fortran-order": np.asfortranarray(points),
        "float32": points.astype(np.float32),
        "integer": np.round(points * 1000).astype(np.int64),
        "list of lists": points.tolist(),
        "legacy open3d": o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)),
        "tensor open3d": tensor,
    }


@pytest.mark.parametrize("form", list(_forms(OBJECT)))
def test_every_array_form_is_accepted_and_never_written(model, form, tmp_path):
    value = _forms(OBJECT)[form]
    before = np.array(
        value
        if not hasattr(value, "point") and not hasattr(value, "points")
        else (
            value.point.positions.numpy() if hasattr(value, "point") else np.asarray(value.points)
        )
    )
    for descriptor in (model, FPFHTransformer(radius="auto", normal_radius="auto")):
        out = descriptor.transform(value)
        assert out.shape[0] == len(OBJECT) and np.isfinite(out).all()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RegistrationWarning)
        result = register(value, before.astype(np.float64), model)  # the same coordinates
    np.testing.assert_allclose(result.transformation, np.eye(4), atol=1e-6)
    after = np.array(
        value
        if not hasattr(value, "point") and not hasattr(value, "points")
        else (
            value.point.positions.numpy() if hasattr(value, "point") else np.asarray(value.points)
        )
    )
    np.testing.assert_array_equal(before, after)


def test_memory_mapped_input(model, tmp_path):
    np.save(tmp_path / "cloud.npy", OBJECT)
    mapped = np.load(tmp_path / "cloud.npy", mmap_mode="r")
    np.testing.assert_array_equal(model.transform(mapped), model.transform(OBJECT))
    assert FPFHTransformer(radius="auto", normal_radius="auto").transform(mapped).shape == (
        1024,
        33,
    )
    assert register(mapped, OBJECT, model).converged


# ------------------------------------------------------------------ bad input, the API
_LINE = np.c_[np.linspace(0.0, 1.0, 400), np.zeros((400, 2))]
_NAN = OBJECT.copy()
_NAN[[3, 7]] = np.nan
BAD_INPUTS = {
    "NaN rows": (_NAN, ValueError, "2 point(s) with NaN"),
    "wrong shape": (OBJECT[:, :2], ValueError, "minimum of 3 is required"),
    "empty": (np.empty((0, 3)), ValueError, "empty point cloud"),
    "all duplicates": (np.ones((300, 3)), ValueError, "coincide"),
    "collinear": (_LINE, ValueError, "collinear"),
    "too few points": (OBJECT[:40], ValueError, "too few"),
    "strings": (np.array([["a", "b", "c"]] * 200), ValueError, "real numbers"),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_source_gets_a_clear_error_naming_it(model, case):
    cloud, error, message = BAD_INPUTS[case]
    with pytest.raises(error, match=message.replace("(", r"\(").replace(")", r"\)")):
        register(cloud, OBJECT, model)


@pytest.mark.parametrize(
    "case",
    ["near-duplicate points", "tiny extent", "huge extent"],
)
def test_awkward_but_valid_clouds_register(model, case):
    source, target = OTHER_SAMPLE @ TURN.T, OBJECT
    if case == "near-duplicate points":  # every point twice, 1e-9 apart
        jitter = np.random.default_rng(0).normal(scale=1e-9, size=source.shape)
        source = np.concatenate([source, source + jitter])
    scale = {"tiny extent": 1e-6, "huge extent": 1e6}.get(case, 1.0)
    result = register(source * scale, target * scale, model)
    truth = _pose(TURN.T, np.zeros(3))
    assert result.converged and rotation_error_deg(result.transformation, truth) < 5.0
    assert np.linalg.norm(result.transformation[:3, 3]) < 0.05 * scale


def test_planar_cloud_warns_and_no_overlap_is_flagged(model):
    rng = np.random.default_rng(0)
    plane = np.c_[rng.uniform(size=(800, 2)), np.zeros(800)]
    with pytest.warns(RegistrationWarning, match="planar"):
        register(plane, plane @ TURN.T, model)
    other = make_object(1024, shape_seed=30, sample_seed=1)  # a different object
    with pytest.warns(RegistrationWarning, match="did not converge"):
        result = register(other, OBJECT, model)
    assert not result.converged


def test_symmetric_shape_is_flagged_ambiguous(model):
    from o3d_rpointhop.datasets.synthetic import _box_surface

    rng = np.random.default_rng(1)
    box = _box_surface(rng, 1500, np.array([1.0, 0.6, 0.3]))
    other = _box_surface(rng, 1500, np.array([1.0, 0.6, 0.3]))
    with pytest.warns(RegistrationWarning, match="ambiguous"):
        result = register(other, box, model)
    assert result.converged and result.ambiguous


# ------------------------------------------------------------------ property tests
finite = st.floats(-1e3, 1e3, allow_nan=False, width=64)
any_float = st.floats(allow_nan=True, allow_infinity=True, width=64)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(arrays(np.float64, st.tuples(st.integers(0, 300), st.integers(1, 4)), elements=any_float))
def test_transform_gives_a_result_or_a_clear_value_error(points):
    model = RPointHopTransformer.pretrained(n_components=8)
    try:
        out = model.transform(points)
    except ValueError as exc:
        assert str(exc)  # a message, not a crash deep in numpy
        return
    assert out.shape == (len(points), 8) and np.isfinite(out).all()


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    arrays(np.float64, st.tuples(st.integers(0, 400), st.just(3)), elements=finite),
    st.floats(-1e6, 1e6, allow_nan=False),
)
def test_register_gives_a_result_or_a_clear_value_error(points, offset):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RegistrationWarning)
            result = register(points + offset, points @ TURN.T)
    except ValueError as exc:
        assert str(exc)
        return
    assert np.isfinite(result.transformation).all()
    assert 0.0 <= result.fitness <= 1.0 and np.isfinite(result.inlier_rmse)


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
    import o3d_rpointhop.cli as cli

    monkeypatch.setattr(cli, "MAX_OUTPUT_BYTES", 1000)
    assert main(["describe", "obj.npy", "-o", "big.npy"]) == EXIT_ERROR
    assert "--force" in capsys.readouterr().err and not (files / "big.npy").exists()
    assert main(["describe", "obj.npy", "-o", "big.npy", "--force"]) == EXIT_OK
    assert main(["fit", "obj.npy", "other.npy", "-o", "model"]) == EXIT_OK
    assert (files / "model").is_file() and not (files / "model.npz").exists()
    RPointHopTransformer.load(files / "model")


def test_cli_help_lists_the_exit_statuses(capsys):
    for args in (["--help"], ["register", "--help"]):
        with pytest.raises(SystemExit):
            main(args)
        text = capsys.readouterr().out
        assert "exit status:" in text and "3  register/demo finished" in text
