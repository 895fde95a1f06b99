"""Pair by pair, what a rerun of a benchmark changed: successes and McNemar's test.

Compares two result files of the same benchmark and seed (``modelnet40.json``,
``bunny.json``), method by method and protocol by protocol, on the pairs both hold:
successes before and after (and up to symmetry where the records say), the pairs
only one side registered, and McNemar's exact two-sided p-value
(:func:`o3d_rpointhop.evaluation.metrics.mcnemar`). An earlier version of a file is
read from git as ``REV:path``.

Usage: python benchmarks/compare_results.py OLD.json NEW.json [--json]
       python benchmarks/compare_results.py HEAD~1:benchmarks/results/bunny.json \\
           benchmarks/results/bunny.json
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
from pathlib import Path

import numpy as np

from o3d_rpointhop.evaluation.metrics import mcnemar

#: Success thresholds when a protocol states none (ModelNet40: unit-sphere shapes).
DEFAULT_TOLERANCE = (5.0, 0.05)


def _read(spec: str) -> dict:
    if ":" in spec and not Path(spec).exists():
        return json.loads(
            subprocess.run(["git", "show", spec], capture_output=True, text=True, check=True).stdout
        )
    return json.loads(Path(spec).read_text())


def _tolerance(protocol: dict) -> tuple[float, float]:
    """The protocol's success thresholds in the records' units (the bunny states mm,
    its records hold metres)."""
    text = protocol.get("success")
    if not text:
        return DEFAULT_TOLERANCE
    rotation, translation, unit = re.search(
        r"< ([\d.]+) deg and translation error < ([\d.]+) ?(mm)?", text
    ).groups()
    return float(rotation), float(translation) / (1000.0 if unit == "mm" else 1.0)


def _flags(records: list[dict], tol: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    ok = np.array(
        [r["rotation_error_deg"] < tol[0] and r["translation_error"] < tol[1] for r in records]
    )
    sym = np.array([bool(r.get("symmetric")) for r in records])
    return ok, ok | sym


def compare(old: dict, new: dict) -> list[dict]:
    """One row per protocol and method held by both files."""
    rows = []
    for name, protocol in new["protocols"].items():
        before = old["protocols"].get(name)
        if before is None or "records" not in protocol or "records" not in before:
            continue
        tol = _tolerance(protocol)
        for method, records in protocol["records"].items():
            if method not in before["records"]:
                continue
            was = {r.get("pair", str(i)): r for i, r in enumerate(before["records"][method])}
            now = {r.get("pair", str(i)): r for i, r in enumerate(records)}
            pairs = [p for p in now if p in was]
            a_ok, a_sym = _flags([was[p] for p in pairs], tol)
            b_ok, b_sym = _flags([now[p] for p in pairs], tol)
            test = mcnemar(b_ok, a_ok)
            has_sym = any("symmetric" in now[p] for p in pairs)
            rows.append(
                {
                    "protocol": name,
                    "method": method,
                    "pairs": len(pairs),
                    "before": int(a_ok.sum()),
                    "after": int(b_ok.sum()),
                    "before_up_to_symmetry": int(a_sym.sum()) if has_sym else None,
                    "after_up_to_symmetry": int(b_sym.sum()) if has_sym else None,
                    "gained": test["a_only"],
                    "lost": test["b_only"],
                    "p_value": test["p_value"],
                }
            )
    return rows


def markdown(rows: list[dict]) -> str:
    lines = [
        "| protocol | method | pairs | before | after | up to symmetry | gained / lost "
        "| McNemar p |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        sym = (
            f"{r['before_up_to_symmetry']} -> {r['after_up_to_symmetry']}"
            if r["before_up_to_symmetry"] is not None
            else "-"
        )
        lines.append(
            f"| {r['protocol']} | {r['method']} | {r['pairs']} | {r['before']} | {r['after']} "
            f"| {sym} | {r['gained']} / {r['lost']} | {r['p_value']:.3g} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", help="a result file, or REV:path for a committed one")
    parser.add_argument("new")
    parser.add_argument("--json", action="store_true", help="print JSON instead of Markdown")
    args = parser.parse_args(argv)
    rows = compare(_read(args.old), _read(args.new))
    print(json.dumps(rows, indent=1) if args.json else markdown(rows), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
