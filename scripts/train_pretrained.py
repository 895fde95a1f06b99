"""Fit the pretrained object models shipped in o3d_rpointhop/data/ (docs/model_card.md).

Both are fitted on the ModelNet40 train subset of ../shared/data (or --data): 1024
points drawn at random from each shape's 2048 (the paper's protocol).

* ``modelnet40``: the paper's object settings (four hops). The file also holds the
  descriptors' first 128 principal axes, which
  ``RPointHopTransformer.pretrained(n_components=K)`` uses; ``pretrained()`` gives the
  full descriptor.
* ``object``: ``register()``'s default, one hop of 96 neighbours, chosen on the
  training shapes for success and time together (benchmarks/object_model_selection.py).

Usage: python scripts/train_pretrained.py [--name modelnet40|object] [--data PATH]
       [--output PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import load_modelnet40
from o3d_rpointhop.descriptors._pretrained import PRETRAINED_MODELS

ROOT = Path(__file__).resolve().parents[1]

#: Each shipped object model's fit parameters (beyond fit_subsample and random_state).
MODELS = {
    "modelnet40": {"n_components": 128},
    "object": {"n_neighbors": (96,), "hop_sizes": (1.0,), "lrf_neighbors": 96},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--name", choices=sorted(MODELS), default="modelnet40")
    parser.add_argument("--data", default=None)
    parser.add_argument("--output", default=None)
    args = parser.parse_args()
    output = args.output or str(ROOT / "o3d_rpointhop" / "data" / PRETRAINED_MODELS[args.name])
    train = load_modelnet40("train", args.data)
    model = RPointHopTransformer(fit_subsample=1024, random_state=0, **MODELS[args.name])
    start = time.perf_counter()
    model.fit(list(train.points))
    seconds = time.perf_counter() - start
    model.save(output)
    card = {
        "data": f"{Path(train.source).name} ({len(train)} shapes, "
        f"{len(set(train.labels.tolist()))} classes)",
        "params": {k: v for k, v in model.get_params().items() if k not in ("n_jobs", "progress")},
        "n_features_out": int(model.selected_[-1].size),
        "channels_per_hop": [int(s.size) for s in model.selected_],
        "fit_seconds": round(seconds, 2),
        "file_bytes": os.path.getsize(output),
    }
    print(json.dumps(card, indent=2, default=str))


if __name__ == "__main__":
    main()
