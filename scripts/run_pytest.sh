#!/usr/bin/env bash
# Run pytest with the given interpreter; "no tests collected" (exit 5) is a failure, not a pass.
# Usage: scripts/run_pytest.sh PYTHON [pytest args...]
set -uo pipefail
py="$1"; shift
"$py" -m pytest "$@"
rc=$?
if [[ $rc -eq 5 ]]; then
    echo "run_pytest: no tests ran for: $*" >&2
    exit 1
fi
exit $rc
