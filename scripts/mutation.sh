#!/bin/sh
# Mutation testing of the modules behind the headline numbers (the metrics, RANSAC, the
# consensus, the frames, the correspondences; [tool.mutmut] in pyproject.toml) with
# mutmut, one command. Not part of CI: it runs the selected tests once per mutant.
#
# Prints every mutant in exactly one of mutmut's statuses (mutmut's own counts,
# `mutmut export-cicd-stats`, whose total is the number of mutants), then every mutant
# that did not end killed, with its status; docs/testing.md lists them with the reason
# each one survives.
#
# Usage: sh scripts/mutation.sh [extra mutmut run arguments, e.g. --max-children 2]
set -eu
cd "$(dirname "$0")/.."
.venv/bin/python -m pip install -q --disable-pip-version-check "mutmut>=3.3"
rm -rf mutants
.venv/bin/mutmut run "$@" || true
.venv/bin/python - <<'PY'
# Every mutant's status, as mutmut names it (mutmut.stats.status_by_exit_code: the
# exit code of the mutant's test run), read from mutmut's own records.
import collections
import json
import pathlib

from mutmut.stats import status_by_exit_code

statuses = {}
for meta in sorted(pathlib.Path("mutants").rglob("*.py.meta")):
    for name, code in json.loads(meta.read_text())["exit_code_by_key"].items():
        statuses[name] = status_by_exit_code[code]
counts = collections.Counter(statuses.values())
print("mutants:", len(statuses), "=", " + ".join(f"{n} {s}" for s, n in counts.most_common()))
assert sum(counts.values()) == len(statuses)
for name, status in sorted(statuses.items()):
    if status != "killed":
        print(f"{status}: {name}")
PY
