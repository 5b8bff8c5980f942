"""Every entry point, four kinds of bad input: a bad number, a non-finite number, a missing file, an unwritable
output (`CASES`), then more refusals with the fragment each line must hold (`MORE`).  Each is one `error:` line,
exit 2, no traceback, and nothing written.  A command that has no input of a kind (no number, no file to read,
nothing it writes) has no case of it."""
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
    "experiments.finetune": {"number": (["--online-steps", "0"], "positive integer"),
                             "finite": (["--online-mix", "nan"], "finite number"),
                             "missing": (["--dataset-path", "{tmp}/none.hdf5"], "none.hdf5"),
                             "output": ([*EXPERIMENT, "--out", "{f}/x"], "not writable")},
    "experiments.fidelity": {"number": (["--bc-updates", "0"], "positive integer"),
                             "finite": (["--td3bc-updates", "nan"], "integer"),
                             "output": (["--out", "{f}/x"], None)},
    "experiments.scan_checkpoints": {"number": (["--run", "{tmp}", "--steps", "0"], "positive integer"),
                                     "missing": (["--run", "{tmp}/none", "--steps", "10"], "none/run.json"),
                                     "output": (["--run", "{tmp}/none", "--steps", "10", "--out", "{f}/x"], None)},
    "experiments.report": {"missing": (["{tmp}/none"], "none"),
                           "output": (["results/mujoco_medium/default-20261202b", "--plot", "{f}/x.png"], None)},
    "offrl_jax.data": {"number": (["generate", "hopper-random", "--transitions", "0"], "positive integer"),
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
    "benchmarks.online": {"number": (["--steps", "0"], "positive integer"),
                          "output": (["--quick", "--out", "{f}/x"], None)},
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


# more refusals, each with a fragment of its one line: (module, arguments, fragment)
MORE = [
    # a bad number, a non-finite number, a value out of range
    ("experiments.theory", ["--eps", "nan"], "finite number >= 0"),
    ("experiments.theory", ["--eps", "-5"], "finite number >= 0"),
    ("experiments.theory", ["--delta", "0"], "(0, 1)"),
    ("experiments.theory", ["--betas", "2"], "[0, 1]"),
    ("experiments.theory", ["--mdps", "x"], "positive integer"),
    ("experiments.adroit_door", ["--scale", "inf"], "finite number"),
    ("experiments.adroit_door", ["--alpha", "nan"], "finite number"),
    ("experiments.adroit_random_scores", ["--episodes", "1"], "integer in [2, 1000000]"),
    ("offrl_jax.data", ["info", ""], "got an empty string"),
    ("experiments.mujoco_medium", ["--seeds", "100000000"], "up to 1,024 (a variant's seeds train as one program"),
    ("experiments.ablation", ["--seeds", "2000"], "up to 1,024"),
    ("offrl_jax.data", ["generate", "hopper-medium", "--transitions", "0"], "positive integer"),
    ("offrl_jax.data", ["generate", "hopper-medium", "--transitions", "-5"], "positive integer"),
    ("benchmarks.throughput", ["--seeds", "0"], "positive integer"),
    ("benchmarks.throughput", ["--transitions", "0"], "positive integer"),
    ("benchmarks.throughput", ["--target-s", "nan"], "finite number > 0"),
    ("benchmarks.throughput", ["--reps", "0"], "positive integer"),
    ("experiments.mujoco_medium", ["--alpha", "inf"], "finite number"),
    ("experiments.mujoco_medium", ["--algo", "bc"], "has no effect on the BC baseline"),
    ("experiments.ablation", ["--algo", "bc"], "the BC baseline has none to compare"),
    ("experiments.mujoco_medium", ["--updates", "1e26"], "positive integer below 2**31"),
    ("benchmarks.parallel", ["--seeds", "0"], "positive integer"),
    ("experiments.mujoco_medium", ["--seed-offset", "99999999999999999999999"], "expected a seed"),
    ("offrl_jax.data", ["generate", "hopper-medium", "--transitions", "10", "--seed", "-1"], "expected a seed"),
    ("experiments.theory", ["--seed", "-1"], "expected a seed"),
    ("experiments.theory", ["--actions", "99999999999999999"], "expected an integer in [2, 1000]"),
    ("experiments.adroit_random_scores", ["--seed", "-1"], "expected a seed"),
    ("experiments.report", [str(ROOT / "results/figure2/hopper-edac"), "--overlay"], "give --plot too"),
    ("experiments.report", [str(ROOT / "results/figure2/hopper-edac"), "--aggregate", "agg.png"],
     "--aggregate takes two or more studies"),
    ("experiments.mujoco_medium", ["--cql-weight", "1", "--cql-actions", "0"], "cql_actions = 0 must be >= 1"),
    ("experiments.mujoco_medium", ["--algo", "rebrac", "--noise-clip", "-1"], "noise_clip = -1.0 must be >= 0"),
    ("experiments.mujoco_medium", ["--policy-noise", "-0.5"], "policy_noise = -0.5 must be >= 0"),
    ("experiments.mujoco_medium", ["--algo", "td3bc_cql", "--cql-temperature", "0"],
     "cql_temperature = 0.0 must be positive"),
    ("experiments.mujoco_medium", ["--cql-weight", "-5"], "cql_weight = -5.0 must be >= 0"),
    ("benchmarks.parallel", ["--cases", "gpu"], "invalid choice"),
    # a missing file
    ("benchmarks.throughput", ["--markdown", "/nonexistent.jsonl"], "/nonexistent.jsonl"),
    ("experiments.report", ["/nonexistent/run"], "/nonexistent/run"),
    ("experiments.mujoco_medium", ["--config", "/nonexistent/config.json"], "/nonexistent/config.json"),
    ("experiments.mujoco_medium", ["--config", str(ROOT / "tests")], "tests: a directory without a config.json"),
    ("experiments.mujoco_medium", ["--dataset-path", ""], "empty string"),
    ("experiments.mujoco_medium", ["--out", "runs/a\tb"], "without control characters"),
    ("experiments.mujoco_medium", ["--coordinator", "notanaddress", "--num-processes", "2", "--process-id", "0"],
     "expected HOST:PORT"),
    ("experiments.mujoco_medium", ["--coordinator", "localhost:-5", "--num-processes", "2", "--process-id", "0"],
     "port in [1, 65535]"),
    ("experiments.mujoco_medium", ["--keep-checkpoints", "99999999999999999999"], "integer >= 0 below 2**31"),
    ("experiments.mujoco_medium", ["--algo", "iql", "--actor-lr-decay", "x"], "expected an integer, got 'x'"),
    ("experiments.mujoco_medium", ["--algo", "edac", "--num-critics", "2.5"], "expected an integer, got '2.5'"),
]


@pytest.mark.parametrize("module, args, fragment", MORE)
def test_more_bad_values_are_refused_in_one_line(tmp_path, module, args, fragment):
    result = run_module(module, *args, cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr and lines and lines[-1].startswith("error: "), result.stderr
    assert fragment in lines[-1], lines[-1]
    assert not any(tmp_path.iterdir())  # nothing written
