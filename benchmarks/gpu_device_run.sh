#!/usr/bin/env bash
# The GPU backend on a real GPU in one call of a lent machine (docs/gpu.md, "Measuring on a
# GPU"): installs, then tests, measures and checks it, each step under its own `timeout`,
# writing its results under $OUT as it goes, in at most about 4 minutes 40 s (a deadline of
# 280 s: the asymptotic check, last, takes what is left of it).
#
#   bash benchmarks/gpu_device_run.sh             # on the GPU machine ($OUT set by the tool)
#   bash benchmarks/gpu_device_run.sh --emulate   # the same steps, small, on this CPU
#
# Steps (the issue's numbers):
#   install  the carried wheels (.whl/: mcap, orjson, zstandard) into /tmp/site, corraoi
#            itself with --no-deps (no rerun-sdk there: the tests that need it skip)
#   1 tests  tests/test_gpu.py and tests/test_drill_gpu.py, every CUDA test enabled
#   2 bench  benchmarks/bench_gpu.py: start-up (compile and cached load apart), run-slots/s per
#            policy at 1e5 and 1e6 runs x T = 1e4, the paper workload warm, then the variants
#            (launch shapes, kernel.cu's switches CAI_LOG_TEST and CAI_FP64) side by side
#   4 means  benchmarks/gpu_means.py: 1e6 runs of UCB, CUCB, TS, CTS on I1 at T = 1e4
#            against the CPU engine's means at 4,000 runs (benchmarks/gpu_cpu_reference.json),
#            for the default kernel and each switch variant (so that a faster one can become
#            the default with its means checked)
#   3 asymp  benchmarks/gpu_asymptotics.py on I2, 10,000 runs, the horizon that the time left
#            (at most 60 s) allows, chosen from a pilot run; its figure
# (4 runs before 3: it is short, and 3 takes whatever time is left.) STEPS="2 4" runs only
# those steps (after the install), for a rerun of what failed.
#
# $OUT gets at most 7 files: env.txt, log.txt (every step's output), summary.txt (the table
# printed last), bench.json, means.json, asymptotics.json, asymptotics.png. Exit status 0
# when every step ended well (a step that failed or timed out is in the table and the log).
set -u
cd "$(dirname "$0")/.."
MODE=cuda
if [[ "${1:-}" == "--emulate" ]]; then
    MODE=emulate
elif [[ -n "${1:-}" ]]; then
    echo "gpu_device_run.sh: unknown argument '$1' (expected --emulate or nothing)" >&2
    exit 2
fi
PY=${PYTHON:-python3}
OUT=${OUT:-$PWD/gpu-run-out}
mkdir -p "$OUT"
LOG=$OUT/log.txt
: >"$LOG"
T0=$(date +%s)
DEADLINE=$((T0 + 280)) # the asymptotic check takes what is left of this
export PYTHONUNBUFFERED=1
ROWS=()
FAILED=0
# the kernels whose means step 4 checks: the default and each switch of bench_gpu's VARIANTS
MEANS_VARIANTS=(--variant "" --variant "CAI_FP64=1" --variant "CAI_LOG_TEST=1:ts,cts"
    --variant "CAI_LOG_TEST=2:ts,cts")
STEPS=${STEPS:-1 2 3 4}
want() { [[ " $STEPS " == *" $1 "* ]]; }

# step NAME LIMIT CMD...: CMD under `timeout LIMIT`, its output into the log as it comes;
# a row for the summary.
step() {
    local name=$1 limit=$2
    shift 2
    local start=$SECONDS rc status
    echo "=== $name (at most $limit s): $*" | tee -a "$LOG"
    timeout --kill-after=5 "$limit" "$@" 2>&1 | tee -a "$LOG"
    rc=${PIPESTATUS[0]}
    case $rc in
    0) status=ok ;;
    124 | 137) status="TIMED OUT at $limit s" ;;
    *) status="FAILED (exit $rc)" ;;
    esac
    ((rc == 0)) || FAILED=$((FAILED + 1))
    ROWS+=("| $name | $status | $((SECONDS - start)) |")
    summary >"$OUT/summary.txt.partial" && mv "$OUT/summary.txt.partial" "$OUT/summary.txt"
}

summary() {
    echo "| step | result | s |"
    echo "|---|---|---:|"
    printf '%s\n' "${ROWS[@]}"
    OUT=$OUT "$PY" - <<'EOF'
import json, os
from pathlib import Path

out = Path(os.environ["OUT"])
def load(name):
    try:
        return json.loads((out / name).read_text())
    except (OSError, ValueError):
        return None
bench, means, asym = load("bench.json"), load("means.json"), load("asymptotics.json")
rows = []
variant_lines = []
if bench:
    print(f"\ndevice: {bench.get('device', '?')}")
    rates = bench.get("rates", {})
    big = {p: max(r.values()) for p, r in rates.items() if r}
    index = [p for p in big if "ts" not in p]
    sampling = [p for p in big if "ts" in p]
    for label, names, target in (("UCB", ["ucb"], 1e11), ("Beta-TS", ["ts"], 2e10),
                                 ("every index policy", index, 6.7e10),
                                 ("every sampling policy", sampling, 1.3e10)):
        got = [big[n] for n in names if n in big]
        if got:
            worst = min(got)
            who = min((n for n in names if n in big), key=big.get)
            rows.append((f"{label}, run-slots/s (best size)", f">= {target:.2g}",
                         f"{worst:.3g}" + (f" ({who})" if len(names) > 1 else ""),
                         worst >= target))
    paper = bench.get("paper_workload_s")
    if paper:
        rows.append((f"paper workload ({paper['runs']} runs) warm, s (best)", "<= 1.0",
                     f"{paper['best']:.3f}", paper["best"] <= 1.0))
    by_policy = {}
    for v in bench.get("variants", []):
        by_policy.setdefault(v["policy"], []).append(v)
    for policy, vs in by_policy.items():
        base = next((v for v in vs if v["variant"] == "default"), None)
        best = max(vs, key=lambda v: v["run_slots_per_s"])
        gain = best["run_slots_per_s"] / base["run_slots_per_s"] if base else float("nan")
        variant_lines.append(f"| {policy} | {base['run_slots_per_s'] if base else 0:.3g} | "
                             f"{best['variant']} | {best['run_slots_per_s']:.3g} | {gain:.2f} |")
if means:
    for variant in dict.fromkeys(r.get("variant", "default") for r in means["rows"]):
        vrows = [r for r in means["rows"] if r.get("variant", "default") == variant]
        worst = max(vrows, key=lambda r: abs(r["z"]))
        rows.append((f"GPU vs CPU means ({variant}), largest |z| ({worst['policy']})",
                     f"<= {means['z_limit']}", f"{abs(worst['z']):.2f}",
                     all(r["within"] for r in vrows)))
if asym:
    rows.append(("asymptotic check: horizon", "-", f"{asym['horizon']:.3g}", True))
    rows.append(("UCB regret per unit of ln T", "> 0", f"{asym['ucb_slope_per_ln_t']:.1f}",
                 asym["ucb_slope_per_ln_t"] > 0))
if rows:
    print("\n| figure | target | measured | met |\n|---|---|---:|---|")
    for label, target, got, ok in rows:
        print(f"| {label} | {target} | {got} | {'yes' if ok else 'NO'} |")
if variant_lines:
    print("\n| policy | default, run-slots/s | fastest variant | its run-slots/s | gain |")
    print("|---|---:|---|---:|---:|")
    print("\n".join(variant_lines))
EOF
}

if [[ $MODE == cuda ]]; then
    export CORRAOI_CACHE_DIR=/tmp/corraoi-cache CUPY_CACHE_DIR=/tmp/corraoi-cupy-cache
    rm -rf "$CORRAOI_CACHE_DIR" "$CUPY_CACHE_DIR"
    step install 45 bash -c "$PY -m pip install -q --no-index --no-deps --no-compile \
        --no-cache-dir --upgrade --target /tmp/site .whl/*.whl && \
        ($PY -m pip install -q --no-index --no-deps --no-build-isolation -e . || \
         echo 'corraoi not installed: it is imported from the checkout (PYTHONPATH)')"
    export PYTHONPATH=/tmp/site:$PWD${PYTHONPATH:+:$PYTHONPATH}
    {
        nvidia-smi 2>&1 | head -20
        "$PY" - <<'EOF'
import sys
print("python", sys.version.split()[0], sys.executable)
for name in ("numpy", "numba", "cupy", "click", "pandas", "pyarrow", "matplotlib", "mcap",
             "orjson", "zstandard", "pytest", "xdist", "corraoi"):
    try:
        mod = __import__(name)
        print(name, getattr(mod, "__version__", "?"), getattr(mod, "__file__", ""))
    except Exception as exc:
        print(name, "NOT IMPORTABLE:", type(exc).__name__, exc)
try:
    import cupy
    from cupy_backends.cuda.libs import nvrtc
    print("cuda runtime", cupy.cuda.runtime.runtimeGetVersion(),
          "driver", cupy.cuda.runtime.driverGetVersion(), "nvrtc", nvrtc.getVersion())
except Exception as exc:
    print("cuda versions: NOT READ:", type(exc).__name__, exc)
EOF
        command -v g++ nvcc
    } >"$OUT/env.txt" 2>&1
    cat "$OUT/env.txt" >>"$LOG"
    export CORRAOI_GPU_DEVICE=cuda
    # -v: each test's result is in the log as it ends, even if the step runs out of time; the
    # drill's emulated capture tests (tens of seconds of CPU, nothing about the GPU) stay out
    want 1 && step "1 tests" 100 "$PY" -m pytest -v -p no:cacheprovider -n 8 tests/test_gpu.py \
        tests/test_drill_gpu.py -k "not emulate"
    want 2 && step "2 bench" 90 "$PY" benchmarks/bench_gpu.py --startup --variants --repeat 2 \
        --json "$OUT/bench.json"
    want 4 && step "4 means" 45 "$PY" benchmarks/gpu_means.py --json "$OUT/means.json" \
        "${MEANS_VARIANTS[@]}"
    RUNS=10000 PILOT=20000
    BUDGET=$((DEADLINE - $(date +%s) - 30)) # seconds of simulation left for step 3
    ((BUDGET > 60)) && BUDGET=60
else
    export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
    "$PY" -c "import sys, numpy; print('python', sys.version.split()[0], 'numpy',
numpy.__version__, '(emulated GPU device)')" >"$OUT/env.txt" 2>&1
    export CORRAOI_GPU_DEVICE=emulate
    want 1 && step "1 tests" 120 "$PY" -m pytest -q -p no:cacheprovider tests/test_gpu.py \
        -k "known_answers and not on_the_gpu"
    want 2 && step "2 bench" 180 "$PY" benchmarks/bench_gpu.py --device emulate --quick --startup \
        --variants --repeat 1 --policies ucb,cts --paper-runs 4 --json "$OUT/bench.json"
    want 4 && step "4 means" 120 "$PY" benchmarks/gpu_means.py --device emulate --gpu-runs 1000 \
        --cpu-runs 500 --horizon 500 --json "$OUT/means.json" "${MEANS_VARIANTS[@]}"
    RUNS=100 PILOT=500 BUDGET=1
fi
if ! want 3; then
    :
elif ((BUDGET >= 1)); then
    step "3 asymp" $((BUDGET + 30)) "$PY" benchmarks/gpu_asymptotics.py \
        --device "$CORRAOI_GPU_DEVICE" --runs "$RUNS" --budget "$BUDGET" --pilot "$PILOT" \
        -o "$OUT/asymptotics.png" --json "$OUT/asymptotics.json"
else
    ROWS+=("| 3 asymp | not run: no time left of the 290 s | 0 |")
fi
summary | tee "$OUT/summary.txt.partial" && mv "$OUT/summary.txt.partial" "$OUT/summary.txt"
echo "total $(($(date +%s) - T0)) s, $FAILED step(s) not ok; files in $OUT: $(ls "$OUT" | tr '\n' ' ')"
((FAILED == 0))
