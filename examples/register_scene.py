"""Register two indoor scans, as the 3DMatch benchmark does: with the shipped scene model,
and with FPFH through the consensus (the better of the two on indoor scans).

With the shared data present (or ``O3D_RPOINTHOP_DATA`` naming it), the pair is a
3DMatch fragment pair from a scene the scene model never saw; without it, two views of a
synthetic room. ``RPointHopTransformer.pretrained("scene")`` states its own global cloud
size (``registration_points_``: 4096) and global step (``registration_global_method_``:
the consensus), so ``register()`` needs no other argument.
"""

import numpy as np

from o3d_rpointhop import FPFHTransformer, RPointHopTransformer, register
from o3d_rpointhop.datasets import make_room
from o3d_rpointhop.transforms import random_rigid_motion, rotation_error_deg, translation_error

try:
    from o3d_rpointhop.datasets import load_3dmatch_pairs

    pairs = load_3dmatch_pairs(benchmark="3DMatch")
    pair = next(p for p in pairs if "studyroom" in p.scene)
    source, target, truth = pair.source, pair.target, pair.truth
    name = f"3DMatch {pair.scene} fragments {pair.j} -> {pair.i} ({pair.overlap:.0%} overlap)"
except (FileNotFoundError, StopIteration):
    target = make_room(20000, seed=1)
    motion = random_rigid_motion(seed=3)
    source = make_room(20000, seed=2) @ motion[:3, :3].T + motion[:3, 3]
    truth = np.linalg.inv(motion)
    name = "two samplings of a synthetic room"

scene = RPointHopTransformer.pretrained("scene")  # 128 axes, 4096 points, consensus
fpfh = FPFHTransformer()
print(f"{name}: {len(source)} and {len(target)} points")
for label, result in (
    ("R-PointHop scene model", register(source, target, scene)),
    ("FPFH + consensus", register(source, target, fpfh, global_method="consensus")),
):
    print(
        f"{label}: rotation error {rotation_error_deg(result.transformation, truth):.2f} deg, "
        f"translation error {translation_error(result.transformation, truth):.3f} m, "
        f"fitness {result.fitness:.2f}, converged {result.converged}"
    )
