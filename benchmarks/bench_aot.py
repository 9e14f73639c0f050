"""Ahead-of-time kernels, measured (issue 22, item 3): is a built-in family's sweep kernel
compiled ahead of time with ``numba.pycc``, from the very source the engine generates, a
better route than numba's on-disk cache?

For each policy: the AOT module is built in a temporary folder, then, in fresh processes,
its import time (it needs no numba) is set against the seconds numba needs to be imported
and to load the cached kernel, and both kernels advance the same 200 runs of I1 by 9,900
slots on 1 and 2 threads (the engine's threads: a kernel that keeps the GIL gains nothing
from the second). The regret sums must agree: the same decisions.

    python benchmarks/bench_aot.py [ucb ts ...]

numba.pycc is deprecated (NumbaPendingDeprecationWarning); this benchmark only measures.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import warnings

_BUILD = r"""
import sys, time, warnings
warnings.simplefilter("ignore")
from numba.core import types
from numba.core.typing import signature
from numba.pycc import CC
from corraoi.engine import kernels
from corraoi.policies import make_policy
name, where = sys.argv[1], sys.argv[2]
kernel = kernels.kernel_for(make_policy(name).resolve(), record=False)
cc = CC("aot_kernel")
cc.output_dir = where
cc.verbose = False
cc.export("advance", signature(types.void, *kernel.signatures[0]))(kernel.py_func)
start = time.perf_counter()
cc.compile()
print(time.perf_counter() - start)
"""

_RUN = r"""
import json, sys, time
start = time.perf_counter()
name, mode, where = sys.argv[1], sys.argv[2], sys.argv[3]
if mode == "aot":
    sys.path.insert(0, where)
    import aot_kernel
    advance = aot_kernel.advance
    ready = time.perf_counter() - start
    numba_before = "numba" in sys.modules
else:  # numba's import, its CPU target and the cache load
    import numba
    from corraoi.engine import kernels
    from corraoi.policies import make_policy
    kernels.kernel_for(make_policy(name).resolve(), record=False)
    ready = time.perf_counter() - start
    numba_before = False
from corraoi.engine import threads
from corraoi.engine.simulation import Simulation
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy
out = {}
for workers in (1, 2):
    threads.set_workers(workers)
    sim = Simulation(load_instance("I1"), make_policy(name), range(200), 10_000)
    if mode == "aot":
        sim.use_kernel(advance, record=False)
    sim.advance_to(100)
    t = time.perf_counter()
    sim.advance_to(10_000)
    out[workers] = time.perf_counter() - t
print(json.dumps({"ready": ready, "numba_needed": numba_before, "t1": out[1], "t2": out[2],
                  "regret": int(sim.regret.sum())}))
"""


def _python(code: str, *args: str) -> str:
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(done.stderr[-2000:])
    return done.stdout.strip().splitlines()[-1]


def main() -> None:
    warnings.simplefilter("ignore")
    names = sys.argv[1:] or ["ucb", "ts"]
    print("policy  kernel  build s  ready s  1 thread s  2 threads s  regret sum  imports numba")
    for name in names:
        with tempfile.TemporaryDirectory(prefix="corraoi-aot-") as where:
            build = float(_python(_BUILD, name, where))
            for mode in ("numba", "aot"):
                best: dict[str, float] = {}
                got: dict = {}
                for _ in range(3):  # best of 3 fresh processes
                    got = json.loads(_python(_RUN, name, mode, where))
                    for key in ("ready", "t1", "t2"):
                        best[key] = min(best.get(key, 1e9), got[key])
                shown = f"{build:7.1f}" if mode == "aot" else "  cache"
                needs = "yes" if mode == "numba" or got["numba_needed"] else "no"
                print(f"{name:7s} {mode:6s} {shown}  {best['ready']:7.3f}  {best['t1']:10.3f}"
                      f"  {best['t2']:11.3f}  {got['regret']:10d}  {needs}")  # fmt: skip


if __name__ == "__main__":
    main()
