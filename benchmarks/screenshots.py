"""The docs' screenshots of the Rerun views, made again: record, open in the Rerun web
viewer in headless Chromium at 1600 x 900, keep a 256-colour PNG in ``docs/``.

    python benchmarks/screenshots.py [--only run-k4,compare] [--out docs]

Makes (each from a fresh recording, seeds fixed):

* ``run-k4.png``: ``record -p cucb`` on I1 (the quick start), 10,000 slots;
* ``run-k16.png``, ``run-k64.png`` and ``run-k256.png``: cucb on random instances of 16,
  64 and 256 arms (benchmarks/alternate.py's), 10,000 slots; every run with ``--score``
  (its "why this arm" view; beyond 64 arms the score is off by default);
* ``compare-screenshot.png``: ``compare`` of ucb, ts and cts-gauss on I1, seed 2, 1,500 slots;
* ``sweep.png``: the sweep recording of ``sweep -i I1 -p ucb,cucb,cts -n 100 -T 10000``;
* asked by name only (``--only sources-m3-k4,sweep-sources``; the docs show none of them):
  ``sources-mM-kK.png``, ``record -p rhorand-ucb --sources M`` on I1 (K = 4) or the random
  instance of K arms, 10,000 slots; ``sweep-sources.png``, the sweep recording of the four
  rules of UCB with 2 sources (one colour, a marker per rule), 50 runs x 10,000 slots.

Needs Debian's ``chromium``; the browser and the viewers run on 127.0.0.1 and are stopped
at the end. Run from the checkout: it imports ``tests/browser.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from alternate import instance_for  # noqa: E402

from tests.browser import (  # noqa: E402
    Chromium,
    find_chromium,
    save_palette_png,
    serve_rrd,
    settled_screenshot,  # noqa: E402
)

SHOTS = ("run-k4", "run-k16", "run-k64", "run-k256", "compare", "sweep")


def corraoi(*args: str, cwd: Path) -> None:
    env = {**os.environ, "RUST_LOG": "off"}
    done = subprocess.run([sys.executable, "-m", "corraoi.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0:
        raise SystemExit(f"corraoi {' '.join(args)} failed:\n{done.stderr}")


def recording(name: str, work: Path) -> Path:
    """Record what screenshot ``name`` shows; the .rrd to open."""
    if name.startswith("sources-m"):  # sources-m3-k4: a run of several sources
        many, arms = (int(v[1:]) for v in name.removeprefix("sources-").split("-"))
        instance = "I1"
        if arms != 4:
            instance = str(work / f"R{arms}.json")
            Path(instance).write_text(json.dumps(instance_for(arms).to_dict()))
        corraoi("record", "-i", instance, "-p", "rhorand-ucb", "--sources", str(many), "-T",
                "10000", "-s", "1", "-o", f"{name}.mcap", "--rrd", f"{name}.rrd", "--force",
                cwd=work)  # fmt: skip
        return work / f"{name}.rrd"
    if name.startswith("run-k"):
        arms = int(name.removeprefix("run-k"))
        instance = "I1"
        if arms != 4:
            instance = str(work / f"R{arms}.json")
            Path(instance).write_text(json.dumps(instance_for(arms).to_dict()))
        corraoi("record", "-i", instance, "-p", "cucb", "-T", "10000", "-s", "1", "--score",
                "-o", f"{name}.mcap", "--rrd", f"{name}.rrd", "--force", cwd=work)  # fmt: skip
        return work / f"{name}.rrd"
    if name == "compare":
        logs = []
        for policy in ("ucb", "ts", "cts-gauss"):
            corraoi("record", "-p", policy, "-T", "1500", "-s", "2", "-o", f"{policy}.mcap",
                    "--no-rrd", "--force", cwd=work)  # fmt: skip
            logs.append(f"{policy}.mcap")
        corraoi("compare", *logs, "-o", "compare.rrd", "--force", cwd=work)
        return work / "compare.rrd"
    if name == "sweep-sources":
        corraoi("sweep", "-i", "I1", "-p", "rhorand-ucb,mctopm-ucb,chairs-ucb,centralized-ucb",
                "--sources", "2", "-n", "50", "-T", "10000", "-o", "sources-sweep", "--force",
                cwd=work)  # fmt: skip
        return work / "sources-sweep" / "sweep.rrd"
    corraoi("sweep", "-i", "I1", "-p", "ucb,cucb,cts", "-n", "100", "-T", "10000",
            "-o", "I1-sweep", "--force", cwd=work)  # fmt: skip
    return work / "I1-sweep" / "sweep.rrd"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(SHOTS), help="comma list of " + ", ".join(SHOTS))
    ap.add_argument("--out", type=Path, default=ROOT / "docs")
    args = ap.parse_args()
    exe = find_chromium()
    if exe is None:
        raise SystemExit("no chromium: apt-get install chromium")
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    with tempfile.TemporaryDirectory(prefix="corraoi-shots-") as tmp:
        for name in names:
            rrd = recording(name, Path(tmp))
            with serve_rrd(rrd) as url:
                browser = Chromium(exe)
                try:
                    browser.open(url)
                    png = settled_screenshot(browser, wait=6, timeout=240)
                finally:
                    browser.close()
            target = args.out / ("compare-screenshot.png" if name == "compare" else f"{name}.png")
            save_palette_png(png, target)
            print(f"{target}: {target.stat().st_size // 1024} KiB")


if __name__ == "__main__":
    main()
