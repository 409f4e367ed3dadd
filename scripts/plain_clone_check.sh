#!/usr/bin/env bash
# A plain clone (no ../shared beside it) passes: the data-reading test modules run once more in
# a fresh clone of this commit in a temporary directory, where ../shared does not exist. They
# must skip (the suite's one line naming the shared directory appears) and none may fail.
# .ci/run runs this after the main pass. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
PYTHON=${PYTHON:-python3}
if [ -x .venv/bin/python ]; then PYTHON=$PWD/.venv/bin/python; fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
git clone -q . "$tmp/clone"
git -C "$tmp/clone" checkout -q "$(git rev-parse HEAD)"
tests=(
    test/test_euroc.py test/test_dataflash.py test/test_ulog.py test/test_replay_real_bags.py
    test/test_faults.py
    test/test_velocity.py::test_a_violent_handheld_shake_is_no_attitude_error
    test/test_velocity.py::test_a_gyro_fault_in_a_hard_shake_keeps_the_aiding_and_is_found
)
pytest_plugins=()
if "$PYTHON" -c 'import importlib.util as u, sys; sys.exit(u.find_spec("launch_testing") is None)'
then
    pytest_plugins=(-p no:launch_testing -p no:launch_pytest)
fi
status=0
# the clone has no compiled step and no data: nothing may be required of it
out=$(cd "$tmp/clone" && env -u CF_ESTIMATOR_REQUIRE_DATA -u CF_ESTIMATOR_REQUIRE_KERNEL \
      -u CF_ESTIMATOR_DATA_ROOT PYTHONPATH="$tmp/clone" \
      "$PYTHON" -m pytest -q -p no:cacheprovider "${pytest_plugins[@]}" "${tests[@]}" "$@" 2>&1) \
    || status=$?
printf '%s\n' "$out" | tail -4
if [ "$status" -ne 0 ]; then
    echo "plain_clone_check: the data-reading tests fail on a clone without ../shared" >&2
    exit 1
fi
if ! grep -q "skipped: the shared data is not in" <<<"$out"; then
    echo "plain_clone_check: no test skipped for the missing shared data (was it hidden?)" >&2
    exit 1
fi
echo "plain_clone_check: a clone without ../shared passes (data tests skipped, none failed)"
