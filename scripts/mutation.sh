#!/bin/sh
# Mutation testing of the modules behind the headline numbers (the metrics, RANSAC, the
# consensus, the frames, the correspondences; [tool.mutmut] in pyproject.toml) with
# mutmut. Not part of CI: it runs the selected tests once per mutant. Prints every
# mutant that survived; docs/testing.md lists them with the reason each one survives.
#
# Usage: sh scripts/mutation.sh [extra mutmut run arguments]
set -eu
cd "$(dirname "$0")/.."
.venv/bin/python -m pip install -q --disable-pip-version-check "mutmut>=3.3"
rm -rf mutants
.venv/bin/mutmut run "$@" || true
.venv/bin/mutmut results
