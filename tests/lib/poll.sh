# Shell helpers shared by the whole-binary test scripts (sourced, not run).
# wait_for DESCRIPTION SECONDS COMMAND...: polls COMMAND every 50 ms until it succeeds; calls the
# script's own `fail` when SECONDS pass. A deadline on a condition, never a fixed sleep standing
# in for synchronisation.
wait_for() {
  local what="$1" secs="$2"; shift 2
  local end=$((SECONDS + secs))
  until "$@" 2>/dev/null; do
    ((SECONDS < end)) || fail "timed out waiting for $what"
    sleep 0.05
  done
}
