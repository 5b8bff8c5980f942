"""Every entry point, four kinds of bad input: a bad number, a non-finite number, a missing file, an unwritable
output.  Each is one `error:` line, exit 2, no traceback, and nothing written.  A command that has no input of a
kind (no number, no file to read, nothing it writes) has no case of it."""
from pathlib import Path

import pytest

from tests.entry import run_module

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENT = ["--updates", "20000"]  # a valid budget, so that the bad value is what fails

# module: {kind: (arguments, a fragment of the error line or None)}; {f} is a plain file, {tmp} a folder
CASES = {
    "experiments.mujoco_medium": {"number": (["--seeds", "0"], "positive integer"),
                                  "finite": (["--alpha", "nan"], "finite number"),
                                  "missing": (["--dataset-path", "{tmp}/none.hdf5"], "none.hdf5"),
                                  "output": ([*EXPERIMENT, "--out", "{f}/x"], "not writable")},
    "experiments.figure2": {"number": (["--edac-updates", "-1"], "positive integer"),
                            "finite": (["--alpha", "inf"], "finite number"),
                            "missing": (["--config", "{tmp}/none.json"], "none.json"),
                            "output": (["--out", "{f}/x"], "not writable")},
    "experiments.ablation": {"number": (["--seeds", "x"], "positive integer"),
                             "finite": (["--tau", "nan"], "finite number"),
                             "missing": (["--dataset-path", "{tmp}/none.hdf5"], "none.hdf5"),
                             "output": (["--out", "{f}/x"], "not writable")},
    "experiments.lambda_sweep": {"number": (["--lambdas", "2"], None),
                                 "finite": (["--lambdas", "nan"], "finite number"),
                                 "missing": (["--dataset-path", "{tmp}/none.hdf5"], "none.hdf5"),
                                 "output": (["--out", "{f}/x"], "not writable")},
    "experiments.layernorm": {"number": (["--batch-size", "0"], "positive integer"),
                              "finite": (["--actor-lr", "inf"], "finite number"),
                              "missing": (["--dataset-path", "{tmp}/none.hdf5"], "none.hdf5"),
                              "output": (["--out", "{f}/x"], "not writable")},
    "experiments.qtransformer": {"number": (["--eval-episodes", "0"], "positive integer"),
                                 "finite": (["--gamma", "nan"], "finite number"),
                                 "missing": (["--dataset-path", "{tmp}/none.hdf5"], "none.hdf5"),
                                 "output": (["--out", "{f}/x"], "not writable")},
    "experiments.replay": {"number": (["--seeds", "-2"], "positive integer"),
                           "finite": (["--critic-lr", "inf"], "finite number"),
                           "missing": (["--config", "{tmp}/none.json"], "none.json"),
                           "output": (["--out", "{f}/x"], "not writable")},
    "experiments.adroit_door": {"number": (["--seeds", "0"], "positive integer"),
                                "finite": (["--scale", "inf"], "finite number"),
                                "missing": (["--dataset-path", "{tmp}/none.npz"], "none.npz"),
                                "output": (["--out", "{f}/x"], "not writable")},
    "experiments.adroit_random_scores": {"number": (["--episodes", "1"], "integer in"),
                                         "finite": (["--episodes", "inf"], "integer in"),
                                         "output": (["--episodes", "2", "--envs", "pen", "--out", "{f}/x"], None)},
    "experiments.theory": {"number": (["--mdps", "0"], "positive integer"),
                           "finite": (["--gamma", "nan"], "finite number"),
                           "output": (["--mdps", "1", "--states", "3", "--out", "{f}/x"], None)},
    "experiments.report": {"missing": (["{tmp}/none"], "none"),
                           "output": (["results/mujoco_medium/default-20261202b", "--plot", "{f}/x.png"], None)},
    "offrl_jax.datasets": {"number": (["generate", "hopper-random", "--transitions", "0"], "positive integer"),
                           "finite": (["generate", "hopper-random", "--transitions", "nan"], "positive integer"),
                           "missing": (["info", "{tmp}/none.hdf5"], "none.hdf5"),
                           "output": (["generate", "hopper-random", "--transitions", "10", "--out", "{f}/x"], None)},
    "offrl_jax.rollout": {"number": (["{tmp}", "--episodes", "0"], "positive integer"),
                          "finite": (["{tmp}", "--episodes", "inf"], "positive integer"),
                          "missing": (["{tmp}/none"], "none"),
                          "output": (["results/mujoco_medium/default-20261202b", "--video", "{f}/x.gif"], None)},
    "offrl_jax.data.generate.sac": {"number": (["--env", "hopper", "--steps", "0", "--out", "{tmp}/o"], "positive"),
                                    "finite": (["--env", "hopper", "--stop-score", "nan", "--out", "{tmp}/o"],
                                               "finite number"),
                                    "missing": (["--resume", "{tmp}/none"], "nothing to resume"),
                                    "output": (["--env", "hopper", "--steps", "10", "--out", "{f}/x"], None)},
    "offrl_jax.data.generate.ship": {"number": (["--run", "{tmp}", "--level", "medium", "--step", "-1"], "positive"),
                                     "finite": (["--run", "{tmp}", "--level", "medium", "--episodes", "inf"],
                                                "positive"),
                                     "missing": (["--run", "{tmp}/none", "--level", "medium"], "none")},
    "benchmarks.throughput": {"number": (["--seeds", "0"], "positive integer"),
                              "finite": (["--target-s", "nan"], "finite number"),
                              "missing": (["--markdown", "{tmp}/none.jsonl"], "none.jsonl"),
                              "output": (["--quick", "--out", "{f}/x.jsonl"], None)},
    "benchmarks.scaling": {"number": (["--seeds", "0"], "positive integer"),
                           "finite": (["--updates", "inf"], "positive integer")},
    "benchmarks.profile": {"number": (["--updates", "0"], "positive integer"),
                           "finite": (["--transitions", "nan"], "positive integer"),
                           "output": (["--out", "{f}/x.jsonl"], None)},
    "benchmarks.memory": {"number": (["--seeds", "0"], "positive integer"),
                          "finite": (["--transitions", "inf"], "positive integer"),
                          "output": (["--out", "{f}/x.jsonl"], None)},
    "benchmarks.flops": {"number": (["--batch", "0"], "positive integer"),
                         "finite": (["--batch", "nan"], "positive integer")},
    "benchmarks.handwritten": {"number": (["--seeds", "0"], "positive integer"),
                               "finite": (["--calls", "inf"], "positive integer")},
    "benchmarks.device_check": {"number": (["--transitions", "0"], "positive integer"),
                                "finite": (["--budget-s", "nan"], "positive integer"),
                                "output": (["--out", "{f}/x.jsonl"], None)},
    "benchmarks.unifloral": {"number": (["--unifloral", "{tmp}", "--updates", "0"], "positive integer"),
                             "finite": (["--unifloral", "{tmp}", "--updates", "inf"], "positive integer"),
                             "missing": (["--unifloral", "{tmp}/none"], "none")},
    "benchmarks.parallel": {"number": (["--seeds", "0"], "positive integer"),
                            "finite": (["--start-after", "nan"], "positive integer")},
}


@pytest.mark.parametrize("module, kind", [(m, k) for m, kinds in CASES.items() for k in kinds])
def test_every_entry_point_refuses_bad_input_in_one_line(tmp_path, module, kind):
    args, fragment = CASES[module][kind]
    (tmp_path / "f").write_text("a plain file")
    args = [a.format(f=tmp_path / "f", tmp=tmp_path) for a in args]
    result = run_module(module, *args)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr and lines and lines[-1].startswith("error: "), result.stderr
    assert fragment is None or fragment in lines[-1], lines[-1]
    if kind == "output":
        assert any(w in lines[-1] for w in ("not writable", "not a directory", "is a file")), lines[-1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]  # nothing written
