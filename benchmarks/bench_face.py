"""The Python face's speed (issue 33): what a notebook or a test waits for.

* ``import corraoi`` against a bare ``python -c pass``: whole processes, best of --repeat
  (target: within 0.05 s);
* ``corraoi.record`` of 10,000 slots, MCAP log and ``.rrd``, in a warm process (the kernels
  compiled and Rerun imported by a first call; target: 0.15 s);
* ``Sweep.record("worst")`` against one ``corraoi.record`` of the same run (target: the same);
* ``corraoi.show`` outside Jupyter (the web viewer served on 127.0.0.1, then closed), warm;
* ``import rerun_notebook`` with the widget's assets served by corraoi, and with
  rerun-notebook's own ``serve-local`` (which gzips its 67 MB WebAssembly first);
* the first ``corraoi.show`` in a fresh Jupyter kernel, timed around the cell with nbclient
  (``import corraoi`` ran in the cell before; target: 3 s).

    python benchmarks/bench_face.py [--repeat 5]

Best of --repeat (median in brackets). Uses its own kernel cache unless CORRAOI_CACHE_DIR is
set.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def timed(fn: Callable[[], object], repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        out.append(time.perf_counter() - start)
    return out


def process(code: str) -> Callable[[], object]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}

    def run() -> None:
        subprocess.run([sys.executable, "-c", code], env=env, check=True)

    return run


def first_show_in_a_fresh_kernel(log: Path, work: Path) -> tuple[float, float]:
    """(the import cell, the show cell) in seconds, in a new kernel (nbclient)."""
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell("import corraoi"),
        nbformat.v4.new_code_cell(f"shown = corraoi.show({str(log)!r})"),
        nbformat.v4.new_code_cell("assert shown.kind == 'notebook', shown"),
    ])  # fmt: skip
    client = NotebookClient(nb, kernel_name="python3", timeout=120,
                            resources={"metadata": {"path": str(work)}})  # fmt: skip
    took = []
    with client.setup_kernel():
        for i, cell in enumerate(nb.cells):
            start = time.perf_counter()
            client.execute_cell(cell, i)
            took.append(time.perf_counter() - start)
    errors = [o for c in nb.cells for o in c.outputs if o.get("output_type") == "error"]
    if errors:
        raise SystemExit(f"the show notebook failed: {errors[0]['ename']}: {errors[0]['evalue']}")
    return took[0], took[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    n = args.repeat
    work = Path(tempfile.mkdtemp(prefix="corraoi-bench-face-"))
    os.environ.setdefault("CORRAOI_CACHE_DIR", str(work / "cache"))
    os.chdir(work)
    rows: list[tuple[str, list[float], str]] = []

    bare = timed(process("pass"), n)
    imp = timed(process("import corraoi"), n)
    rows.append(("python -c pass (process)", bare, ""))
    rows.append(("python -c 'import corraoi' (process)", imp,
                 f"+{min(imp) - min(bare):.3f} s (target <= 0.05)"))  # fmt: skip

    import corraoi

    corraoi.record("cucb", "I1", seed=0, horizon=10_000, path="warm.mcap")  # warm-up
    rec = timed(lambda: corraoi.record("cucb", "I1", seed=0, horizon=10_000, path="r.mcap",
                                       force=True), n)  # fmt: skip
    rows.append(("corraoi.record, 10,000 slots, MCAP + .rrd (warm)", rec, "target <= 0.15"))

    sw = corraoi.sweep("I1", ["ucb", "cucb"], runs=20, horizon=10_000, out="sweep")
    row = sw.notable["cells"]["ucb"]["worst"]  # type: ignore[index]
    sw.record("worst", policy="ucb", path="drill.mcap", force=True)  # warm-up
    drill = timed(lambda: sw.record("worst", policy="ucb", path="drill.mcap", force=True), n)
    same = timed(lambda: corraoi.record("ucb", "I1", seed=int(row["seed"]), horizon=10_000,
                                        path="same.mcap", force=True), n)  # fmt: skip
    rows.append((f"corraoi.record of that run (ucb, seed {row['seed']})", same, ""))
    rows.append(('Sweep.record("worst", policy="ucb")', drill,
                 f"x{min(drill) / min(same):.2f} of one record"))  # fmt: skip

    log = Path("r.mcap").resolve()

    def web() -> None:
        corraoi.show(log, notebook=False).close()

    web()  # warm-up (rerun imported)
    rows.append(("corraoi.show outside Jupyter: web viewer up, then closed", timed(web, n), ""))

    # why corraoi serves the widget's assets itself: rerun-notebook's own serve-local gzips
    # the 67 MB WebAssembly when it is imported
    k = max(1, min(n, 3))
    own = process("from corraoi.face.viewing import serve_widget_assets\n"
                  "serve_widget_assets(); import rerun_notebook")  # fmt: skip
    rows.append(("import rerun_notebook, assets served by corraoi (process)", timed(own, k), ""))
    env = {**os.environ, "RERUN_NOTEBOOK_ASSET": "serve-local"}

    def serve_local() -> None:
        subprocess.run([sys.executable, "-c", "import rerun_notebook"], env=env, check=True,
                       capture_output=True)  # fmt: skip

    rows.append(("import rerun_notebook, its own serve-local (process)", timed(serve_local, k),
                 ""))  # fmt: skip

    kernel = [first_show_in_a_fresh_kernel(log, work) for _ in range(k)]
    rows.append(("fresh kernel: the 'import corraoi' cell", [k[0] for k in kernel], ""))
    rows.append(("fresh kernel: the first corraoi.show cell", [k[1] for k in kernel],
                 "target <= 3"))  # fmt: skip

    cores = os.cpu_count()
    print(f"\n{cores} cores, best of {n} (median in brackets; fresh kernels: "
          f"{len(kernel)}), seconds")
    for name, values, note in rows:
        cell = f"{min(values):7.3f} ({statistics.median(values):.3f})"
        print(f"{name:58s}{cell:>18s}  {note}")


if __name__ == "__main__":
    main()
