"""Where a command's training runs: the CPU cores of this process, and the other processes of a multi-process run.

* `use_cpu_cores`: on the CPU, one single-threaded XLA device per core of this process, so that one variant's
  members (seeds x sweep values) split over every core (`offrl_jax.driver.member_layout`).
* `start_processes`: join a run spread over processes started elsewhere (`--distributed`, or `--coordinator`,
  `--num-processes`, `--process-id`).
* `start_local_processes`: `--processes N`, one run over N processes of this machine that this command starts.

Each must run before JAX starts its backend.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

from offrl_jax.system.cli import UsageError
from offrl_jax.system.workers import USER_XLA_FLAGS, cpu_flags, process_cores


def use_cpu_cores() -> None:
    """Give this process one single-threaded XLA device per core it may use, so that a variant's members split over
    the cores (`offrl_jax.driver.member_layout`).  A lone member runs as fast as under XLA's own thread pool
    (benchmarks/README.md, "One variant on both cores").  A GPU or TPU ignores these flags."""
    import jax._src.xla_bridge as xla_bridge

    if process_cores() > 1 and not xla_bridge.backends_are_initialized():
        os.environ["XLA_FLAGS"] = cpu_flags(process_cores())


def check_backend() -> None:
    """Start JAX's backend now, before anything is written: a bad XLA_FLAGS (no devices, say) is one line here.
    (An unknown flag still ends the process inside XLA, but nothing has been written yet.)"""
    import jax

    try:
        jax.devices()
    except RuntimeError as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        given = {name: os.environ.get(USER_XLA_FLAGS if name == "XLA_FLAGS" else name, os.environ.get(name, ""))
                 for name in ("JAX_PLATFORMS", "XLA_FLAGS")}  # the user's own (the command adds CPU flags)
        said = "; ".join(f"{name}={value!r}" for name, value in given.items() if value)
        raise UsageError(f"JAX could not start ({first[:200]}){'; ' + said if said else ''}") from None


def start_processes(args) -> bool:
    """Join the other processes of a multi-process run if the flags ask for one; returns whether this process
    writes the run's files (process 0, or the only one)."""
    manual = (args.coordinator, args.num_processes, args.process_id)
    if args.processes > process_cores():
        raise UsageError(f"--processes {args.processes}: this command may use {process_cores()} core(s), one process "
                         "each at most")
    if args.processes > 1 and (args.distributed or any(x is not None for x in manual)):
        raise UsageError("--processes starts its own processes on this machine; --distributed and --coordinator "
                         "join processes started elsewhere: give one or the other")
    if not args.distributed and all(x is None for x in manual):
        return True
    if args.distributed and any(x is not None for x in manual):
        raise UsageError("--distributed reads the cluster's environment; --coordinator/--num-processes/--process-id "
                         "set the processes by hand: give one or the other")
    if not args.distributed and any(x is None for x in manual):
        raise UsageError("--coordinator, --num-processes and --process-id go together")
    if not args.distributed and args.process_id >= args.num_processes:
        raise UsageError(f"--process-id {args.process_id} must be below --num-processes {args.num_processes}")
    if args.out is None and args.resume is None:
        raise UsageError("a multi-process run needs --out (or --resume): every process must name the same directory")
    from offrl_jax.system import distributed
    if not args.distributed:  # a missing partner would otherwise look like a silent hang
        print(f"process {args.process_id} of {args.num_processes}: joining the run at {args.coordinator} (waiting up "
              "to 5 minutes for the others)", file=sys.stderr, flush=True)
    try:
        distributed.initialize(*manual) if not args.distributed else distributed.initialize()
    except (RuntimeError, ValueError) as e:
        raise UsageError(f"jax.distributed could not start ({' '.join(str(e).split())[:300]})") from None
    return distributed.is_writer()


def _child_argv(argv, args, out: Path) -> list[str]:
    """The command line of the other processes of a --processes run: this one's, without --processes, with the
    output directory this process chose."""
    argv, kept, skip = list(sys.argv[1:] if argv is None else argv), [], False
    for token in argv:
        if skip:
            skip = False
        elif token == "--processes":
            skip = True
        elif not token.startswith("--processes="):
            kept.append(token)
    return kept + (["--out", str(out)] if args.out is None and args.resume is None else [])


def start_local_processes(args, argv, prog: str, out: Path):
    """With --processes N > 1: this process becomes process 0 of a run over N processes of this machine and starts
    the others (`offrl_jax.system.distributed.LocalProcesses`, to be closed at the end); otherwise None."""
    if args.processes <= 1:
        return None
    from offrl_jax.system.distributed import LocalProcesses

    local = LocalProcesses(args.processes, prog, _child_argv(argv, args, out))
    local.start()
    return local
