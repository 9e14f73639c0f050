"""The ``corraoi`` command line: a thin click shell over the library.

Heavy modules (the numba engine, rerun, mcap) are imported inside the commands so that
``corraoi --help`` stays fast.
"""

from __future__ import annotations

import json
from typing import Any

import click

from corraoi._version import __version__
from corraoi.text import safe_text

from .common import OneLineGroup, handle_errors
from .options import HORIZON


@click.group(
    "corraoi",
    cls=OneLineGroup,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
)
@click.version_option(__version__, prog_name="corraoi")
def main() -> None:
    """Correlated Age-of-Information bandits: simulate, record, replay, compare and diff.

    \b
    A sensor sends one update per slot over one of K channels whose successes depend on a
    shared hidden state. Scheduling policies learn which channel keeps the data fresh.
    \b
    Start with:
      corraoi record --policy cucb      simulate one run, stream it to runs/*.mcap and *.rrd
      corraoi instance show I1          the model and its theory (competitive arms, C, bounds)
      corraoi compare A.mcap B.mcap     recorded runs side by side (no recomputation)
      corraoi diff A.mcap B.mcap        where two recorded runs diverge (exit 0/1/2)
      corraoi sweep --policy all        every policy over 200 paired runs, regret with 95% CI
      corraoi reproduce -o paper        the paper's simulations, figures and tables
      corraoi policies                  every policy (and your plug-ins) with its parameters
      corraoi sweep exp.toml -o grid    a grid of experiments, resumable, on Dask if asked
      corraoi sweep ... --backend gpu   built-in policies on a CUDA GPU (docs/gpu.md)
    """
    from corraoi.face.about import say_compiles

    # Rerun's own log lines (a file writer stopped by a full disk, ...) would come before our
    # one line about the same thing: we report its problems ourselves. The first use of a
    # policy family compiles its kernel (seconds): say so, on stderr.
    say_compiles(lambda message: click.echo(
        f"corraoi: {message}" + ("" if message.startswith(" ") else " ..."), err=True
    ))  # fmt: skip


# ---------------------------------------------------------------------------- instances


@main.group()
def instance() -> None:
    """Inspect instances: built-ins and instance files."""


@instance.command("list")
@handle_errors
def instance_list() -> None:
    """List the built-in instances."""
    from corraoi.face.about import builtin_instances

    for inst, th in builtin_instances():
        name = inst.name
        mu = " ".join(f"{v:g}" for v in th.mu)
        click.echo(
            f"{name}  K={inst.K} states={inst.n_states}  mu=[{mu}]  best arm {th.best_arm + 1}"
            f"  C={th.C}"
        )


@instance.command("show")
@click.argument("spec", metavar="NAME|PATH")
@click.option("--horizon", "-T", type=HORIZON, default=10_000, show_default=True,
              help="Horizon at which the regret bounds are evaluated.")  # fmt: skip
@click.option("--bound-beta", type=float, default=None,
              help="beta of Theorem 3 (CTS, Gaussian priors; needs beta > 1) "
              "[default: 2].")  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of a table.")
@handle_errors
def instance_show(spec: str, horizon: int, bound_beta: float | None, as_json: bool) -> None:
    """Show an instance and its theory: mu, gaps, phi, pseudo-gaps, competitive arms, C.

    Arms and states are numbered from 1. phi is the expected pseudo-reward of each arm with
    respect to the best arm k*; an arm l != k* is competitive when mu* - phi_{l,k*} <= 0.
    """
    from corraoi.face.about import instance_theory

    found = instance_theory(spec, horizon=horizon, bound_beta=bound_beta)
    inst, th, bounds, chain = found.instance, found.theory, found.bounds, found.chain
    if as_json:
        out: dict[str, Any] = {"name": inst.name, "instance": inst.to_dict(), **th.to_dict()}
        out["bounds"] = {k: b.to_dict() for k, b in bounds.items()}
        if chain is not None:
            out["markov"] = {
                "stationary": [float(v) for v in inst.p],
                "t_mix": chain.t_mix,
                "mixing_definition": "first t with max_x TV(P^t(x, .), pi) <= 1/4",
                "spectral_gap": chain.spectral_gap,
            }
        click.echo(json.dumps(out, indent=2))
        return
    kind = "Markov" if chain is not None else "i.i.d."
    click.echo(f"instance {inst.name}: K={inst.K} arms, {inst.n_states} hidden states ({kind})")
    if inst.transition is not None and chain is not None:
        click.echo("transition matrix P (row: from, column: to):")
        width = max(len(s) for s in inst.state_names)
        for s, row in zip(inst.state_names, inst.transition, strict=True):
            click.echo(f"  {s:>{width}}  " + "  ".join(f"{v:6.4g}" for v in row))
        click.echo(chain.describe())
        click.echo("p below is the stationary law of P")
    click.echo(
        "p      " + "  ".join(f"{s}={v:g}" for s, v in zip(inst.state_names, inst.p, strict=True))
    )
    click.echo("")
    names = [safe_text(n) for n in inst.arm_names]
    nw = max(10, *(len(n) for n in names))  # a long arm name widens its column, never shifts
    header = f"{'arm':>4} {'name':>{nw}} {'Y(x)':>{max(6, 2 * inst.n_states)}} "
    header += f"{'mu':>7} {'gap':>7} {'phi':>7} {'p-gap':>7}  role"
    click.echo(header)
    for k in range(inst.K):
        row = " ".join(str(int(v)) for v in inst.Y[k])
        if k == th.best_arm:
            role = "best"
        elif k in th.strictly_competitive:
            role = "competitive (strictly)"
        elif k in th.competitive:
            role = "competitive"
        else:
            role = "non-competitive"
        click.echo(
            f"{k + 1:>4} {names[k]:>{nw}} {row:>{max(6, 2 * inst.n_states)}} "
            f"{th.mu[k]:7.4g} {th.gaps[k]:7.4g} {th.phi[k]:7.4g} {th.pseudo_gap[k]:7.4g}  {role}"
        )
    click.echo("")
    comp = ", ".join(str(a + 1) for a in th.competitive) or "none"
    click.echo(f"best arm k* = {th.best_arm + 1} (mu* = {th.mu_star:g})")
    if len(th.best_tied) > 1:
        tied = ", ".join(str(a + 1) for a in th.best_tied)
        click.echo(f"note: arms {tied} tie for the best mean; k* is the lowest index")
    click.echo(f"competitive sub-optimal arms: {comp}   C = {th.C}")
    click.echo(f"upper bounds on the expected AoI regret at T = {horizon}:")
    for b in bounds.values():
        value = f"{b.value:.6g}" if b.value is not None else "n/a"
        click.echo(f"  {b.theorem:28s} {value:>12}  ({b.note})")


# ---------------------------------------------------------------------------- policies


@main.command("policies")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of a table.")
@handle_errors
def policies_cmd(as_json: bool) -> None:
    """List the policies: built-ins, then plug-ins found through entry points.

    \b
    Plug-ins are also taken by path: --policy FILE.py:Class or --policy package.module:Class
    (see docs/extending.md). A broken entry point is listed with its error; the rest work.
    --param NAME=VALUE sets a parameter of every listed policy that declares NAME.
    """
    from corraoi.face.about import paper_policies, policy_entries

    entries = policy_entries()
    if as_json:
        click.echo(json.dumps({"policies": entries}, indent=2))
        return
    for e in entries:
        if e["status"] != "ok":
            click.echo(f"{e['name']:22s} BROKEN ({e['source']}): {e['error']}")
            continue
        params = ", ".join(f"{k}={v['default']:g}" for k, v in e["params"].items()) or "-"
        where = "" if e["source"] == "built-in" else f"  [{e['source']}]"
        click.echo(f"{e['name']:22s} {params:22s} {e['summary']}{where}")
    click.echo("")
    seen: set[str] = set()
    for e in entries:
        for k, v in e.get("params", {}).items():
            if k not in seen:
                seen.add(k)
                click.echo(
                    f"--param {k}=VALUE  {v['help']} (default {v['default']:g}, {v['range']})"
                )
    click.echo(
        "--policy all: the paper's twelve ("
        + ", ".join(paper_policies())
        + ")"
    )


# Commands defined in their own modules (they import the face inside their bodies).
# --- command registrations (keep this block at the end) ---
from .compare import compare  # noqa: E402
from .figure import figure  # noqa: E402
from .record import record  # noqa: E402
from .replay import replay  # noqa: E402
from .reproduce import reproduce  # noqa: E402
from .sweep import sweep  # noqa: E402
from .viewer import diff, info, recover  # noqa: E402

main.add_command(sweep)
main.add_command(reproduce)
main.add_command(replay)
main.add_command(compare)
main.add_command(diff)
main.add_command(info)
main.add_command(recover)
main.add_command(figure)
main.add_command(record)
main.add_command(__import__("corraoi.cli.export", fromlist=["export"]).export)


def run() -> None:
    """The ``corraoi`` program (console script, ``python -m corraoi``): :func:`main`, then
    leave without the interpreter's teardown.

    Tearing down the modules of a process that loaded numba and a kernel takes 0.2-0.4 s
    on the 2-core benchmark machine (freeing LLVM's objects one by one), more than a
    ``record --no-rrd`` of 10 slots does (benchmarks/bench_start.py). Once the command is
    done, the exit handlers run (``atexit``: temporary folders, loggers, worker pools) and
    the output is flushed as a normal exit does, and the process ends; every file the
    command wrote is closed by then. Threads still running (a viewer's server, a Dask
    client) get the normal exit that waits for them. ``main`` itself (tests, CliRunner)
    exits normally, and so does a command that served Foxglove live.
    """
    import os
    import sys
    import threading

    try:
        main(prog_name="corraoi")
        code: Any = 0
    except SystemExit as exc:
        code = exc.code
    import atexit

    threads = sys.modules.get("corraoi.engine.threads")
    if threads is not None:
        threads.shutdown()  # the engine's idle threads: the command is done with them
    run_exit_handlers = getattr(atexit, "_run_exitfuncs", None)  # CPython's, since 3.0
    # A live Foxglove server may still be sending its last messages from its own (native)
    # threads after stop(): the normal exit gives them the time (tests/test_foxglove_live.py).
    if threading.active_count() > 1 or run_exit_handlers is None or "foxglove" in sys.modules:
        sys.exit(code)
    if code is None:
        code = 0
    elif not isinstance(code, int):
        print(code, file=sys.stderr)
        code = 1
    run_exit_handlers()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (| head) or stream: nothing to save
            pass
    os._exit(code)
