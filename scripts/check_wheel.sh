#!/bin/sh
# Packaging check: build a wheel from this checkout, install it (not editable, with the
# [plot] extra the demo draws with) in a fresh virtual environment, and from outside the
# checkout load the shipped models and run the demo. Needs .venv (scripts/setup.sh);
# dependencies come from pip's cache when setup.sh has filled it.
set -eu
cd "$(dirname "$0")/.."
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
echo "wheel check: building"
# setuptools copies sources into ./build and keeps files it copied before: a module
# deleted from the package would still be shipped. Start from an empty build folder.
rm -rf build
.venv/bin/python -m pip wheel -q --disable-pip-version-check --no-deps -w "$work/dist" . \
    > "$work/build.log" 2>&1 || { cat "$work/build.log" >&2; exit 1; }
echo "wheel check: installing $(basename "$work"/dist/*.whl) in a fresh environment"
.venv/bin/python -m venv "$work/venv"
"$work/venv/bin/python" -m pip install -q --disable-pip-version-check "$(ls "$work"/dist/*.whl)[plot]" \
    > "$work/install.log" 2>&1 || { cat "$work/install.log" >&2; exit 1; }
cd "$work"
"$work/venv/bin/python" - <<'PY'
import pathlib

import o3d_rpointhop
from o3d_rpointhop import RPointHopTransformer

where = pathlib.Path(o3d_rpointhop.__file__).resolve()
assert "site-packages" in where.parts, f"imported from {where}, not from the wheel"
full = RPointHopTransformer.pretrained()
objects = RPointHopTransformer.pretrained("object")
scene = RPointHopTransformer.pretrained("scene")
assert (full.n_features_out_, objects.n_features_out_, scene.n_features_out_) == (1624, 24, 96)
assert (where.parent / "py.typed").is_file(), "py.typed is not in the wheel"
print(f"wheel check: the three shipped models load from {where.parent}")

# The compiled consensus kernels compile (or load from numba's cache) from the wheel.
import numpy as np
from o3d_rpointhop import register
from o3d_rpointhop.datasets import make_object

cloud = make_object(1500, shape_seed=2)
result = register(cloud + [0.05, 0.0, 0.0], cloud, scene, global_method="consensus")
assert abs(result.transformation[0, 3] + 0.05) < 1e-3, result.transformation
print("wheel check: the consensus step runs")
PY
"$work/venv/bin/o3d-rpointhop" demo --output-dir "$work/demo" > "$work/demo.log"
test -s "$work/demo/before_after.png" && test -s "$work/demo/transform.txt"
echo "wheel check: the demo ran ($(head -n 2 "$work/demo.log" | tail -n 1 | sed 's/^ *//'))"
