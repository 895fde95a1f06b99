"""A hash over registrations: every global method, every ICP variant, multiway, batch.

Run before and after a change that must not alter what the library computes (a
refactor); equal hashes prove it did not. Only the public API is used, and every
setting is named explicitly, so the script measures the code, not a change of defaults.

    python benchmarks/registration_hash.py                # synthetic pairs only
    python benchmarks/registration_hash.py --data ../shared/data   # plus real pairs

Prints one hash per case and the hash over all of them; ``--json FILE`` writes them.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import warnings

import numpy as np
from scipy.spatial.transform import Rotation


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(np.asarray(a, dtype=np.float64)).tobytes())
    return h.hexdigest()[:16]


def _result_digest(result) -> str:
    """Transformation, fitness, RMSE, flags and every step's transformation and fitness."""
    parts = [result.transformation, [result.fitness, result.inlier_rmse]]
    parts.append([float(result.converged), float(result.ambiguous)])
    for step in result.steps:
        parts += [step.transformation, [step.fitness, step.inlier_rmse]]
    return _digest(*parts)


def _object_pairs():
    from o3d_rpointhop.datasets import make_object

    pairs = []
    for k in range(3):
        target = make_object(1500, shape_seed=60 + k, sample_seed=1)
        rot = Rotation.random(random_state=100 + k).as_matrix()
        source = make_object(1500, shape_seed=60 + k, sample_seed=2) @ rot.T + [0.3, -0.2, 0.1]
        pairs.append((f"object{k}", source, target))
    return pairs


def _room_pair():
    from o3d_rpointhop.datasets import make_room

    rot = Rotation.from_euler("z", 25, degrees=True).as_matrix()
    return (
        "room",
        make_room(5000, random_state=1) @ rot.T + [0.2, 0.1, 0.0],
        make_room(5000, random_state=2),
    )


def _real_pairs(data):
    from o3d_rpointhop.datasets import load_3dmatch_pairs, load_bunny

    scans = load_bunny(("bun000", "bun045"), data)
    pairs = [("bunny", scans["bun045"].points, scans["bun000"].points)]
    for p in load_3dmatch_pairs(data)[:2]:
        pairs.append((f"3dmatch {p.scene} {p.i}-{p.j}", p.source, p.target))
    return pairs


def cases(data=None):
    """``(name, thunk)`` per case; each thunk returns a digest string."""
    from o3d_rpointhop import FPFHTransformer, RPointHopTransformer, register
    from o3d_rpointhop.batch import register_many

    default = RPointHopTransformer.pretrained(n_components=128)
    objects = RPointHopTransformer.pretrained("object")
    scene = RPointHopTransformer.pretrained("scene")
    fpfh = FPFHTransformer()
    pairs = _object_pairs() + [_room_pair()]
    if data is not None:
        pairs += _real_pairs(data)
    out = []
    full = RPointHopTransformer.pretrained(n_components=None)
    for name, source, _ in pairs[:1] + pairs[3:4]:
        for descriptor_name, descriptor in (
            ("full", full),
            ("object", objects),
            ("scene", scene),
            ("fpfh", fpfh),
        ):

            def describe(s=source, d=descriptor):
                return _digest(d.transform(s))

            out.append((f"{name} descriptors {descriptor_name}", describe))
    for name, source, target in pairs:
        for descriptor_name, descriptor in (("rpointhop", default), ("fpfh", fpfh)):
            for global_method in ("ransac", "consensus", "fgr", "svd"):

                def run(s=source, t=target, d=descriptor, g=global_method):
                    return _result_digest(
                        register(
                            s,
                            t,
                            d,
                            global_method=g,
                            refine="point_to_plane",
                            n_global_points=2048,
                            random_state=0,
                        )
                    )

                out.append((f"{name} {descriptor_name} {global_method}+point_to_plane", run))
        for refine in (
            "point_to_point",
            "generalized",
            "multiscale",
            ["point_to_plane", "symmetry_check"],
            None,
        ):

            def run(s=source, t=target, r=refine):
                return _result_digest(
                    register(
                        s,
                        t,
                        default,
                        global_method="ransac",
                        refine=r,
                        n_global_points=2048,
                        random_state=0,
                    )
                )

            out.append((f"{name} rpointhop ransac+{refine}", run))

        def run_object(s=source, t=target):
            return _result_digest(register(s, t, objects, global_method="ransac", random_state=0))

        out.append((f"{name} object-model ransac+point_to_plane", run_object))

        def run_scene(s=source, t=target):
            return _result_digest(register(s, t, scene, global_method="ransac", random_state=0))

        out.append((f"{name} scene-model ransac+point_to_plane", run_scene))

    def run_icp_only():
        s, t = pairs[0][1], pairs[0][2]
        init = np.eye(4)
        return _result_digest(register(s, t, global_method=None, init=init, random_state=0))

    out.append(("icp from identity", run_icp_only))

    def run_batch():
        chosen = [(s, t) for _, s, t in pairs[:2]]
        results = register_many(chosen, default, global_method="ransac", n_global_points=2048)
        return _digest(*[r.transformation for r in results])

    out.append(("register_many", run_batch))

    def run_multiway():
        from o3d_rpointhop import register_multiway
        from o3d_rpointhop.datasets import make_object

        views = []
        for k in range(4):
            rot = Rotation.random(random_state=200 + k).as_matrix()
            views.append(make_object(1200, shape_seed=77, sample_seed=k) @ rot.T + 0.1 * k)
        result = register_multiway(views, default, random_state=0)
        return _digest(*[p for p in result.poses if p is not None], [len(result.edges)])

    out.append(("register_multiway synthetic", run_multiway))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", help="also register real pairs from this data folder")
    parser.add_argument("--json", help="write the per-case hashes here")
    args = parser.parse_args()
    hashes = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, thunk in cases(args.data):
            hashes[name] = thunk()
            print(f"{hashes[name]}  {name}", flush=True)
    total = hashlib.sha256("".join(hashes.values()).encode()).hexdigest()[:16]
    print(f"{total}  ALL ({len(hashes)} cases)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"all": total, "cases": hashes}, fh, indent=1)


if __name__ == "__main__":
    main()
