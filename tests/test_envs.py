"""The env registry's environment construction."""
import subprocess
import sys


def test_a_mujoco_warning_is_printed_once_per_process():
    """halfcheetah's model warns on every compile under MuJoCo 3.3+: an evaluation makes an env per episode, so the
    same line would fill the log. Each distinct warning is shown once."""
    code = ("from offrl_jax.envs.registry import make_env\n"
            "for _ in range(3):\n"
            "    make_env('halfcheetah').reset(seed=0)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    lines = [line for line in (out.stdout + out.stderr).splitlines() if "WARNING" in line]
    assert len(lines) <= 1, lines
