"""Where a command's training runs on the CPU: one single-threaded XLA device per core of the process, the user's
own XLA_FLAGS kept (and winning) however many processes deep the flags are passed on."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from offrl_jax.system.workers import SINGLE_THREAD_XLA, USER_XLA_FLAGS, cpu_flags


def test_one_single_threaded_device_per_core_and_the_users_flags_last():
    env = {"XLA_FLAGS": "--xla_dump_to=/tmp/x"}
    flags = cpu_flags(2, env)
    assert flags.startswith(SINGLE_THREAD_XLA)
    assert flags.split()[1:] == ["--xla_force_host_platform_device_count=2", "--xla_dump_to=/tmp/x"]
    assert env[USER_XLA_FLAGS] == "--xla_dump_to=/tmp/x"


def test_a_process_started_from_one_with_the_flags_set_gets_its_own_count_not_both():
    parent = {"XLA_FLAGS": ""}
    parent["XLA_FLAGS"] = cpu_flags(2, parent)  # what the command line sets for itself
    child = dict(parent)  # what a worker process pinned to one core inherits
    assert cpu_flags(1, child).split() == [SINGLE_THREAD_XLA, "--xla_force_host_platform_device_count=1"]


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs 2 cores")
def test_the_command_line_gives_a_process_a_device_per_core():
    code = ("from offrl_jax.app.launch import use_cpu_cores; use_cpu_cores(); import jax; "
            "print(jax.device_count(), jax.devices()[0].platform)")
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", USER_XLA_FLAGS)} | {"JAX_PLATFORMS": "cpu"}
    out = subprocess.run(["taskset", "-c", "0,1", sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True, timeout=120).stdout.split()
    assert out == ["2", "cpu"]
