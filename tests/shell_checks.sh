# Counters and PASS/FAIL/SKIP lines shared by the shell tests (sourced, not run).
passed=0
failed=0
skipped=0
pass() {
    echo "PASS  $1"
    passed=$((passed + 1))
}
fail() {
    echo "FAIL  $1"
    [ $# -gt 1 ] && printf '      %s\n' "$2"
    failed=$((failed + 1))
}
skip() {
    echo "SKIP  $1"
    skipped=$((skipped + 1))
}
