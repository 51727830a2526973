#!/usr/bin/env bash
# The README's test command as a new user meets it (issue 11), then once more with the cache it left:
# a clean clone of the committed HEAD, a new venv, HOME pointing at an empty directory (no JAX
# compilation cache, no pip cache); the install, then the tests cold, then the tests warm (same
# HOME, so JAX's persistent cache from the first run is there). Writes the section
# "Test suite on a fresh machine" of benchmarks/RESULTS.md in the checkout it is run from.
#   benchmarks/suite_fresh.sh            (from the repository root; about 20 minutes on 2 cores)
set -u
top=$(git rev-parse --show-toplevel) || { echo "not inside a git checkout"; exit 2; }
head=$(git -C "$top" rev-parse --short HEAD)
root=$(mktemp -d)
trap 'rm -rf "$root"' EXIT
git clone -q "$top" "$root/repo" && cd "$root/repo" || exit 2
python3 -m venv "$root/venv" && source "$root/venv/bin/activate"
export HOME="$root/home" XDG_CACHE_HOME="$root/home/.cache"; mkdir -p "$HOME"
cmd=$(grep -oE 'pip install[^`]*&& *python -m pytest[^`]*' README.md | head -1)
install=${cmd%%&&*}
tests=${cmd#*&& }
echo "fresh clone of $head; install: $install; tests: $tests"
start=$(date +%s); bash -c "$install" > "$root/install.log" 2>&1 || { tail -5 "$root/install.log"; exit 2; }
install_s=$(( $(date +%s) - start ))
load0=$(cut -d' ' -f1-3 /proc/loadavg)
start=$(date +%s); bash -c "$tests" > "$root/cold.log" 2>&1; cold_rc=$?; cold_s=$(( $(date +%s) - start ))
load1=$(cut -d' ' -f1-3 /proc/loadavg)
start=$(date +%s); bash -c "$tests" > "$root/warm.log" 2>&1; warm_rc=$?; warm_s=$(( $(date +%s) - start ))
load2=$(cut -d' ' -f1-3 /proc/loadavg)
cold_line=$(tail -1 "$root/cold.log"); warm_line=$(tail -1 "$root/warm.log")
grep -E "^(FAILED|ERROR)" "$root/cold.log" "$root/warm.log" | head -20
echo "cold: $cold_line (exit $cold_rc, ${cold_s} s); warm: $warm_line (exit $warm_rc, ${warm_s} s); install ${install_s} s"
python3 - "$top/benchmarks" <<EOF
import sys
sys.path.insert(0, sys.argv[1])
from _results import write_section
body = """Command: \`benchmarks/suite_fresh.sh\` at commit $head: a clean clone, a new venv, \`HOME\` an empty
directory (no JAX compilation cache), the README's install (\`$install\`, ${install_s} s), then the README's
test command (\`$tests\`) twice: cold (empty cache) and warm (the cache the first run left).
Machine: $(nproc) CPUs, load average before / between / after: $load0 / $load1 / $load2; default XLA threading,
two pytest-xdist workers (pyproject \`addopts\`).

| run | wall time [s] | result | exit code |
|---|---:|---|---:|
| cold cache | $cold_s | $cold_line | $cold_rc |
| warm cache | $warm_s | $warm_line | $warm_rc |
"""
write_section("Test suite on a fresh machine", body)
EOF
exit $(( cold_rc != 0 || warm_rc != 0 ))
