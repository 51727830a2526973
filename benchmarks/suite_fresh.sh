#!/usr/bin/env bash
# The README's test command as a new user meets it (issue 11), then on other settings (see below):
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
# Three runs of the README's test command in the same fresh clone:
#   cold:   as the README runs it (the suite keeps JAX's persistent cache off: tests/conftest.py);
#   single: single-threaded XLA (each worker pinned to a CPU of its own: an intra-op pool of one thread) with the
#           persistent cache ON and empty (FFR_JAX_TEST_CACHE), so this run fills it;
#   warm:   default threading, the cache the single-threaded run left.
cache="$HOME/jax-cache"
run() {  # name, env assignments...
  local name=$1; shift
  local t0=$(date +%s)
  env "$@" bash -c "$tests" > "$root/$name.log" 2>&1; local rc=$?
  eval "${name}_rc=$rc; ${name}_s=$(( $(date +%s) - t0 )); ${name}_line=\"\$(tail -1 \"$root/$name.log\")\"; ${name}_load=\"$(cut -d' ' -f1-3 /proc/loadavg)\""
}
load0=$(cut -d' ' -f1-3 /proc/loadavg)
run cold
run single FFR_JAX_TEST_CACHE="$cache" FFR_JAX_TEST_ONE_CORE_PER_WORKER=1
run warm FFR_JAX_TEST_CACHE="$cache"
grep -E "^(FAILED|ERROR)" "$root/cold.log" "$root/single.log" "$root/warm.log" | head -20
for name in cold single warm; do eval "echo \"$name: \$${name}_line (exit \$${name}_rc, \$${name}_s s)\""; done
echo "install ${install_s} s"
mkdir -p "$top/benchmarks/results/suite_fresh"
for name in cold single warm; do grep -E "^[0-9.]+s (call|setup)" "$root/$name.log" | head -30 > "$top/benchmarks/results/suite_fresh/$name-durations.txt"; done
python3 - "$top/benchmarks" <<EOF
import sys
sys.path.insert(0, sys.argv[1])
from _results import write_section
body = """Command: \`benchmarks/suite_fresh.sh\` at commit $head: a clean clone, a new venv, \`HOME\` an empty
directory (no JAX compilation cache), the README's install (\`$install\`, ${install_s} s), then the README's
test command (\`$tests\`) three times in that clone. Machine: $(nproc) CPUs, load average (1/5/15 min) before the
first run $load0; two pytest-xdist workers (pyproject \`addopts\`). The suite's own XLA settings
(tests/conftest.py: fusion emitters off, LLVM -O0, the package's scheduler flag) apply to every run.
The 30 slowest setups and calls of each run: \`benchmarks/results/suite_fresh/<run>-durations.txt\`.

| run | settings | wall time [s] | result | exit code | load after |
|---|---|---:|---|---:|---|
| cold | as the README runs it: persistent cache off (the suite's default), default XLA threading | $cold_s | $cold_line | $cold_rc | $cold_load |
| single | single-threaded XLA (\`FFR_JAX_TEST_ONE_CORE_PER_WORKER=1\`: each worker pinned to its own CPU, so XLA's intra-op pool has one thread), persistent cache ON and empty (\`FFR_JAX_TEST_CACHE\`): fills it | $single_s | $single_line | $single_rc | $single_load |
| warm | default threading, persistent cache ON with what the single run left | $warm_s | $warm_line | $warm_rc | $warm_load |
"""
write_section("Test suite on a fresh machine", body)
EOF
exit $(( cold_rc != 0 || single_rc != 0 || warm_rc != 0 ))
