"""Fit the pretrained model shipped in o3d_rpointhop/data/ (see docs/model_card.md).

Paper object settings, fitted on the ModelNet40 train subset of ../shared/data (or
--data): 1024 points drawn at random from each shape's 2048 (the paper's protocol).
The file also holds the descriptors' first 128 principal axes, which
``RPointHopTransformer.pretrained(n_components=K)`` uses; ``pretrained()`` gives the
full descriptor.

Usage: python scripts/train_pretrained.py [--data PATH] [--output PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import load_modelnet40

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", default=None)
    parser.add_argument(
        "--output", default=str(ROOT / "o3d_rpointhop" / "data" / "rpointhop_modelnet40.npz")
    )
    args = parser.parse_args()
    train = load_modelnet40("train", args.data)
    model = RPointHopTransformer(fit_subsample=1024, n_components=128, random_state=0)
    start = time.perf_counter()
    model.fit(list(train.points))
    seconds = time.perf_counter() - start
    model.save(args.output)
    card = {
        "data": f"{Path(train.source).name} ({len(train)} shapes, "
        f"{len(set(train.labels.tolist()))} classes)",
        "params": {k: v for k, v in model.get_params().items() if k not in ("n_jobs", "progress")},
        "n_features_out": int(model.selected_[-1].size),
        "channels_per_hop": [int(s.size) for s in model.selected_],
        "fit_seconds": round(seconds, 2),
        "file_bytes": os.path.getsize(args.output),
    }
    print(json.dumps(card, indent=2, default=str))


if __name__ == "__main__":
    main()
