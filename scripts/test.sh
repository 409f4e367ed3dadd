#!/usr/bin/env bash
# The project's test command (README "Quick start"; CI runs it through .ci/run):
# install this checkout with its test extra, lint, run the whole test suite.
# Extra arguments go to pytest, e.g. `bash scripts/test.sh -k packaging -x`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

PYTHON=${PYTHON:-python3}
export PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_ROOT_USER_ACTION=ignore

# A system Python that refuses pip installs (PEP 668, e.g. Ubuntu 24.04 under ROS 2 Jazzy):
# use a repo-local venv that still sees the system's packages (rclpy, numpy, ...).
if "$PYTHON" - <<'PY'
import os, sys, sysconfig
managed = os.path.exists(os.path.join(sysconfig.get_path("stdlib"), "EXTERNALLY-MANAGED"))
sys.exit(0 if managed and sys.prefix == sys.base_prefix else 1)
PY
then
    [ -x .venv/bin/python ] || "$PYTHON" -m venv --system-site-packages .venv
    PYTHON=.venv/bin/python
fi

# Editable, so the tests and the cf-estimator script both run this checkout's code.
"$PYTHON" -m pip install -q -e '.[test]'
# Put this interpreter's script dir first: new scripts are not always visible through
# pyenv shims or an unactivated venv, and tests call `cf-estimator` by name.
scripts_dir=$("$PYTHON" -c 'import sysconfig; print(sysconfig.get_path("scripts"))')
export PATH="$scripts_dir:$PATH"

# With a C compiler here, the compiled filter step must have been built: its tests fail instead
# of skipping (test/test_kernel.py). Without one, the Python reference runs everything.
if command -v "${CC:-cc}" >/dev/null 2>&1; then
    export CF_ESTIMATOR_REQUIRE_KERNEL=${CF_ESTIMATOR_REQUIRE_KERNEL:-1}
fi

"$PYTHON" -m ruff check .
"$PYTHON" -m pytest -q "$@"
