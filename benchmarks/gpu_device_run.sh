#!/usr/bin/env bash
# The GPU backend on a real GPU in one call of a lent machine (docs/gpu.md, "Measuring on a
# GPU"): installs, then tests, measures and checks it, each step under its own `timeout`,
# writing its results under $OUT as it goes, ending by a deadline (DEADLINE_S, 280 s by
# default: every step's limit is cut to what is left of it, and the asymptotic check takes
# what is left).
#
#   bash benchmarks/gpu_device_run.sh             # on the GPU machine ($OUT set by the tool)
#   bash benchmarks/gpu_device_run.sh --emulate   # the same steps, small, on this CPU
#
# Steps (the issue's numbers):
#   install  the carried wheels (.whl/: mcap, orjson, zstandard) into /tmp/site, corraoi
#            itself with --no-deps (no rerun-sdk there: the tests that need it skip)
#   1 tests  tests/test_gpu.py and tests/test_drill_gpu.py, every CUDA test enabled
#   2 bench  benchmarks/bench_gpu.py: start-up (compile and cached load apart), run-slots/s per
#            policy at 1e5 and 1e6 runs x T = 1e4 with the checkpoints reduced by the kernel
#            and by the array module side by side, the paper workload warm, then the
#            variants (launch shapes, kernel.cu's switches CAI_LOG_TEST and CAI_FP64)
#   4 means  benchmarks/gpu_means.py: 1e6 runs of UCB, CUCB, TS, CTS on I1 at T = 1e4
#            against the CPU engine's means at 4,000 runs (benchmarks/gpu_cpu_reference.json),
#            for the default kernel and each switch variant (so that a faster one can become
#            the default with its means checked)
#   3 asymp  benchmarks/gpu_asymptotics.py on I2, 10,000 runs, the horizon that the time left
#            (at most 60 s) allows, chosen from a pilot run; its figure
# (4 runs before 3: it is short, and 3 takes whatever time is left.)
#
# Chosen by the environment (the defaults are the whole run above):
#   STEPS="2 1 4"     which steps run after the install, in that order (default "1 2 4 3")
#   DEADLINE_S=190    seconds from the start by which the script has ended (default 280):
#                     each step runs under min(its cap, the time left - 25 s), and a step
#                     with less than 5 s left is not run (its row says so)
#   BENCH_ARGS="..."  bench_gpu.py's arguments beside --device and --json
#   MEANS_ARGS="..."  gpu_means.py's arguments beside --device and --json
# A short run, for example (the third GPU run: the tests, every policy at 1e6 runs x T 1e4
# with both reductions, the paper workload, the means; about 90 s, at most 190 s):
#   STEPS="2 1 4" DEADLINE_S=190 BENCH_ARGS="--sizes 1e6x1e4 --reductions kernel,arrays
#     --repeat 2" MEANS_ARGS="--variant default" bash benchmarks/gpu_device_run.sh
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
T0=$(date +%s)
DEADLINE_S=${DEADLINE_S:-280}
if ! [[ $DEADLINE_S =~ ^[1-9][0-9]*$ ]]; then
    echo "gpu_device_run.sh: DEADLINE_S='$DEADLINE_S' (expected whole seconds, more than 0)" >&2
    exit 2
fi
STEPS=${STEPS:-1 2 4 3}
for s in $STEPS; do
    if [[ $s != [1234] ]]; then
        echo "gpu_device_run.sh: STEPS='$STEPS': '$s' is not a step (expected 1, 2, 3, 4)" >&2
        exit 2
    fi
done
DEADLINE=$((T0 + DEADLINE_S))
RESERVE=25 # seconds kept at the end: a step's kill-after (5 s), two summaries (10 s each)
PY=${PYTHON:-python3}
OUT=${OUT:-$PWD/gpu-run-out}
mkdir -p "$OUT"
LOG=$OUT/log.txt
: >"$LOG"
export PYTHONUNBUFFERED=1
ROWS=()
FAILED=0
# the kernels whose means step 4 checks: the default and each switch of bench_gpu's VARIANTS
MEANS_VARIANTS="--variant default --variant CAI_FP64=1 --variant CAI_LOG_TEST=1:ts,cts
    --variant CAI_LOG_TEST=2:ts,cts"

# step NAME CAP CMD...: CMD under `timeout` (CAP seconds, or what is left before the deadline
# if less), its output into the log as it comes; a row for the summary; its exit status in
# STEP_RC (-1: not run).
step() {
    local name=$1 limit=$2
    shift 2
    local left=$((DEADLINE - $(date +%s) - RESERVE))
    ((left < limit)) && limit=$left
    if ((limit < 5)); then
        ROWS+=("| $name | not run: no time left of the $DEADLINE_S s | 0 |")
        FAILED=$((FAILED + 1))
        echo "=== $name: not run (no time left of the $DEADLINE_S s)" | tee -a "$LOG"
        summary >"$OUT/summary.txt.partial" && mv "$OUT/summary.txt.partial" "$OUT/summary.txt"
        STEP_RC=-1
        return
    fi
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
    STEP_RC=$rc
}

summary() {
    echo "| step | result | s |"
    echo "|---|---|---:|"
    printf '%s\n' "${ROWS[@]}"
    OUT=$OUT timeout 10 "$PY" - <<'EOF'
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
reduction_lines = []
if bench:
    print(f"\ndevice: {bench.get('device', '?')}")
    default = bench.get("reduction", "kernel")
    by_reduction = bench.get("rates_by_reduction") or {default: bench.get("rates", {})}
    for reduction, rates in by_reduction.items():
        big = {p: max(r.values()) for p, r in rates.items() if r}
        index = [p for p in big if "ts" not in p]
        sampling = [p for p in big if "ts" in p]
        tag = f"; checkpoints: {reduction}" + (" (default)" if reduction == default else "")
        for label, names, target in (("UCB", ["ucb"], 1e11), ("Beta-TS", ["ts"], 2e10),
                                     ("every index policy", index, 6.7e10),
                                     ("every sampling policy", sampling, 1.3e10)):
            got = [big[n] for n in names if n in big]
            if got:
                worst = min(got)
                who = min((n for n in names if n in big), key=big.get)
                rows.append((f"{label}, run-slots/s (best size{tag})", f">= {target:.2g}",
                             f"{worst:.3g}" + (f" ({who})" if len(names) > 1 else ""),
                             worst >= target))
    if len(by_reduction) == 2:
        (ra, a), (rb, b) = by_reduction.items()
        for p in a:
            for size in a[p]:
                if size in b.get(p, {}):
                    reduction_lines.append(f"| {p} | {size} | {a[p][size]:.3g} | "
                                           f"{b[p][size]:.3g} | {a[p][size] / b[p][size]:.3f} |")
        reduction_head = (f"\n| policy | runs x T | {ra} | {rb} | {ra} / {rb} |"
                          "\n|---|---|---:|---:|---:|")
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
    rel = [r["reduction_rel_error"] for r in means["rows"] if "reduction_rel_error" in r]
    if rel:
        rows.append(("moments at T against the final regrets', largest relative difference",
                     "<= 1e-09", f"{max(rel):.1e}", max(rel) <= 1e-9))
if asym:
    rows.append(("asymptotic check: horizon", "-", f"{asym['horizon']:.3g}", True))
    rows.append(("UCB regret per unit of ln T", "> 0", f"{asym['ucb_slope_per_ln_t']:.1f}",
                 asym["ucb_slope_per_ln_t"] > 0))
if rows:
    print("\n| figure | target | measured | met |\n|---|---|---:|---|")
    for label, target, got, ok in rows:
        print(f"| {label} | {target} | {got} | {'yes' if ok else 'NO'} |")
if reduction_lines:
    print(reduction_head)
    print("\n".join(reduction_lines))
if variant_lines:
    print("\n| policy | default, run-slots/s | fastest variant | its run-slots/s | gain |")
    print("|---|---:|---|---:|---:|")
    print("\n".join(variant_lines))
EOF
}

if [[ $MODE == cuda ]]; then
    export CORRAOI_CACHE_DIR=/tmp/corraoi-cache CUPY_CACHE_DIR=/tmp/corraoi-cupy-cache
    rm -rf "$CORRAOI_CACHE_DIR" "$CUPY_CACHE_DIR"
    step install 30 bash -c "$PY -m pip install -q --no-index --no-deps --no-compile \
        --no-cache-dir --upgrade --target /tmp/site .whl/*.whl && \
        ($PY -m pip install -q --no-index --no-deps --no-build-isolation -e . || \
         echo 'corraoi not installed: it is imported from the checkout (PYTHONPATH)')"
    export PYTHONPATH=/tmp/site:$PWD${PYTHONPATH:+:$PYTHONPATH}
    {
        timeout 10 nvidia-smi 2>&1 | head -20
        timeout 30 "$PY" - <<'EOF'
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
    # drill's emulated capture tests (tens of seconds of CPU, nothing about the GPU) and the
    # tests of this script (run --emulate, on the CPU) stay out
    TESTS=(100 "$PY" -m pytest -v -p no:cacheprovider -n 8 tests/test_gpu.py
        tests/test_drill_gpu.py -k "not emulate and not device_run_script")
    BENCH=(90 "$PY" benchmarks/bench_gpu.py ${BENCH_ARGS:---startup --variants --reductions \
        kernel,arrays --repeat 2} --json "$OUT/bench.json")
    MEANS=(45 "$PY" benchmarks/gpu_means.py ${MEANS_ARGS:-$MEANS_VARIANTS} --json
        "$OUT/means.json")
    RUNS=10000 PILOT=20000 SIM_MAX=60
else
    export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
    "$PY" -c "import sys, numpy; print('python', sys.version.split()[0], 'numpy',
numpy.__version__, '(emulated GPU device)')" >"$OUT/env.txt" 2>&1
    export CORRAOI_GPU_DEVICE=emulate
    TESTS=(120 "$PY" -m pytest -q -p no:cacheprovider tests/test_gpu.py
        -k "known_answers and not on_the_gpu")
    BENCH=(180 "$PY" benchmarks/bench_gpu.py --device emulate ${BENCH_ARGS:---quick --startup \
        --variants --reductions kernel,arrays --repeat 1 --policies ucb,cts --paper-runs 4}
        --json "$OUT/bench.json")
    MEANS=(120 "$PY" benchmarks/gpu_means.py --device emulate ${MEANS_ARGS:---gpu-runs 1000 \
        --cpu-runs 500 --horizon 500 $MEANS_VARIANTS} --json "$OUT/means.json")
    RUNS=100 PILOT=500 SIM_MAX=1
fi
for s in $STEPS; do
    case $s in
    1) step "1 tests" "${TESTS[@]}" ;;
    2)
        step "2 bench" "${BENCH[@]}"
        # a bench that broke (not timed out) while the kernel's reduction was among those it
        # timed: once more with the arrays' alone (the last --reductions counts), so that the
        # fallback's figures come back whatever broke the kernel's
        if ((STEP_RC > 0 && STEP_RC != 124 && STEP_RC != 137)) &&
            [[ " ${BENCH[*]} " =~ --reductions\ [a-z,]*kernel ]]; then
            step "2 bench again, arrays' reduction" "${BENCH[@]}" --reductions arrays
        fi
        ;;
    4) step "4 means" "${MEANS[@]}" ;;
    3)
        # seconds of simulation for step 3: what the deadline leaves after its start-up (30 s)
        BUDGET=$((DEADLINE - $(date +%s) - RESERVE - 30))
        ((BUDGET > SIM_MAX)) && BUDGET=$SIM_MAX
        if ((BUDGET >= 1)); then
            step "3 asymp" $((BUDGET + 30)) "$PY" benchmarks/gpu_asymptotics.py \
                --device "$CORRAOI_GPU_DEVICE" --runs "$RUNS" --budget "$BUDGET" \
                --pilot "$PILOT" -o "$OUT/asymptotics.png" --json "$OUT/asymptotics.json"
        else
            ROWS+=("| 3 asymp | not run: no time left of the $DEADLINE_S s | 0 |")
            FAILED=$((FAILED + 1))
        fi
        ;;
    esac
done
summary | tee "$OUT/summary.txt.partial" && mv "$OUT/summary.txt.partial" "$OUT/summary.txt"
echo "total $(($(date +%s) - T0)) s, $FAILED step(s) not ok; files in $OUT: $(ls "$OUT" | tr '\n' ' ')"
((FAILED == 0))
