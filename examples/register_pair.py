"""Register two scans of an object: one call, the staged pipeline, and Open3D's own RANSAC.

Runs without any data (synthetic object); with ../shared/data present, pass
--bunny to register two real Stanford Bunny scans instead.
"""

import sys

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation

from o3d_rpointhop import (
    MultiScaleICP,
    PointToPlaneICP,
    RANSACGlobal,
    RegistrationPipeline,
    RPointHopTransformer,
    register,
    to_open3d_feature,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.transforms import rotation_error_deg, translation_error

if "--bunny" in sys.argv:
    from o3d_rpointhop.datasets import load_bunny

    scans = load_bunny(("bun000", "bun045"))
    source, target = scans["bun045"].points, scans["bun000"].points
    truth = scans["bun045"].relative_pose(scans["bun000"])
else:
    target = make_object(3000, shape_seed=11, sample_seed=1)
    rotation = Rotation.random(random_state=5).as_matrix()
    source = make_object(3000, shape_seed=11, sample_seed=2) @ rotation.T + [1.0, 0.5, 0.0]
    truth = np.eye(4)
    truth[:3, :3], truth[:3, 3] = rotation.T, -rotation.T @ [1.0, 0.5, 0.0]


def report(name, transformation):
    print(
        f"{name:28s} rotation error {rotation_error_deg(transformation, truth):6.3f} deg, "
        f"translation error {translation_error(transformation, truth):.2e}"
    )


# 1. One call: pretrained R-PointHop, RANSAC, then ICP.
result = register(source, target)
report("register()", result.transformation)
for step in result.steps:
    print(f"    {step.name:8s} fitness {step.fitness:.2f}  {step.seconds:.2f} s  {step.info}")

# 2. The staged pipeline, tuned like a scikit-learn Pipeline.
pipe = RegistrationPipeline(
    [
        ("global", RANSACGlobal(confidence=0.9999)),
        ("coarse", MultiScaleICP()),
        ("fine", PointToPlaneICP(kernel="tukey")),
    ],
    random_state=1,
)
pipe.set_params(fine__max_iteration=80)
report("RegistrationPipeline", pipe.register(source, target).transformation)

# 3. The descriptors inside Open3D's own feature-matching RANSAC.
model = RPointHopTransformer.pretrained()
voxel = result.voxel_size
src_down = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source)).voxel_down_sample(voxel)
tgt_down = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target)).voxel_down_sample(voxel)
reg = o3d.pipelines.registration
o3d.utility.random.seed(0)
ransac = reg.registration_ransac_based_on_feature_matching(
    src_down,
    tgt_down,
    to_open3d_feature(model.transform(src_down)),
    to_open3d_feature(model.transform(tgt_down)),
    True,
    1.5 * voxel,
    reg.TransformationEstimationPointToPoint(False),
    3,
    [reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel)],
    reg.RANSACConvergenceCriteria(1_000_000, 0.999),
)
report("Open3D RANSAC, R-PointHop", np.asarray(ransac.transformation))
