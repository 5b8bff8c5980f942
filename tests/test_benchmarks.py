"""Smoke tests of benchmarks/: the analytic FLOP counter, `--quick --json` keys and one-line refusals (no timing
assertions)."""
import json

import pytest

from benchmarks.flops import eval_flops, mlp_dims, update_flops
from offrl_jax.algos import make_config
from tests.entry import run_module

KEYS = {"algo", "phase", "seeds", "updates_per_s", "compile_s", "gflop_per_update", "achieved_gflops", "peak_gflops",
        "pct_of_peak"}


def test_flop_counts_by_hand():
    actor = mlp_dims(11, (256, 256), 3)
    forward = 2 * 256 * (11 * 256 + 256 * 256 + 256 * 3)
    assert eval_flops(actor, 256) == forward
    # parameter gradient: forward + weight grads + input grads of every layer but the first
    assert eval_flops(actor, 256, "params") == 3 * forward - 2 * 256 * 11 * 256
    bc, _ = update_flops(make_config("bc", "hopper"), "actor_pretrain", 11, 3)
    assert bc == eval_flops(actor, 256, "params")
    # TD3+BC: a call is policy_delay (2) critic updates + one actor update; FLOPs are per update
    td3, count = update_flops(make_config("td3bc", "hopper"), "offline_rl", 11, 3)
    assert td3 == pytest.approx(count.total / 2)
    # EDAC's diversity term makes the critic step second order: more than SAC-N at the same N
    edac, _ = update_flops(make_config("edac", "hopper", num_critics=10), "offline_rl", 11, 3)
    sacn, _ = update_flops(make_config("sacn", "hopper", num_critics=10), "offline_rl", 11, 3)
    assert edac > sacn > td3 > bc


def test_flop_count_of_calql_uses_the_actors_own_widths():
    """Cal-QL with CORL's networks (critics 2x256, actor 3x256): the CQL terms evaluate the actor on 2 B M rows and
    the critics on 3 B M rows; the actor's widths are `actor_hidden`, not the critics'."""
    config = make_config("calql", "hopper", hidden=(256, 256), actor_hidden=(256, 256, 256))
    total, count = update_flops(config, "offline_rl", 11, 3)
    actor, critic = mlp_dims(11, (256, 256, 256), 6), mlp_dims(14, (256, 256), 1)
    terms = dict(count.terms)
    assert terms["CQL: actor fwd on 2 x B*10"] == eval_flops(actor, 2 * 256 * 10)
    assert terms["CQL: critics fwd+grad x2 on 3 x B*10"] == eval_flops(critic, 3 * 256 * 10, "params", 2)
    assert terms["actor fwd+grad"] == eval_flops(actor, 256, "params")
    assert total == count.total


def test_analytic_flops_match_xla_cost_analysis():
    from benchmarks.flops import xla_update_flops
    from offrl_jax.algos import make_algorithm

    config = make_config("bc", "hopper")
    algo = make_algorithm(config, 11, 3, 1000)
    (phase,) = algo.phases(1000)
    analytic, _ = update_flops(config, phase.name, 11, 3)
    xla = xla_update_flops(algo, phase, 11, 3)
    assert analytic <= xla <= 1.15 * analytic  # XLA also counts element-wise ops (a few per cent)


def test_quick_json(capsys, tmp_path):
    from benchmarks.throughput import main

    out = tmp_path / "quick.jsonl"
    earlier = b'{"meta": {"command": "an earlier run"}}\n{"algo": "bc"}'  # saved before; no final newline
    out.write_bytes(earlier)
    results = main(["--json", "--quick", "--out", str(out)])
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.strip()]
    assert len(lines) == len(results) == 1
    record = lines[0]
    assert KEYS <= record.keys()
    assert record["seeds"] == 1 and record["finite"]
    for key in ("updates_per_s", "gflop_per_update", "achieved_gflops", "peak_gflops", "pct_of_peak"):
        assert record[key] > 0
    assert out.read_bytes().startswith(earlier + b"\n")  # appended to, nothing lost
    written = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(written) == 4
    assert "command" in written[2]["meta"] and "date" in written[2]["meta"]
    assert written[3] == record


@pytest.mark.slow  # two fresh JAX processes: ~1 min idle, several under load
def test_memory_json_dataset_is_shared_by_seeds(capsys):
    from benchmarks.memory import main

    assert main(["--algos", "td3bc", "--seeds", "1", "2", "--transitions", "3000", "--json"]) == 0
    one, two = (json.loads(line) for line in capsys.readouterr().out.splitlines() if line.strip())
    assert one["finite"] and two["finite"] and one["peak_rss_mb"] > 0
    assert one["dataset_mb"] == two["dataset_mb"]  # one copy, whatever S
    assert two["state_mb_all_seeds"] == pytest.approx(2 * one["state_mb_all_seeds"], rel=0.01)


def test_handwritten_fused_layer_norm_vjp_matches_autodiff():
    import jax
    import jax.numpy as jnp
    import numpy as np

    from benchmarks.handwritten import ln_relu, ln_relu_fused

    x = jax.random.normal(jax.random.PRNGKey(0), (2, 5, 8))
    g = 1.0 + 0.1 * jax.random.normal(jax.random.PRNGKey(1), (8,))
    b = 0.1 * (jnp.arange(8.0) - 4.0)  # some pre-activations negative: the ReLU mask matters
    dy = jax.random.normal(jax.random.PRNGKey(2), (2, 5, 8))
    out_ref, vjp_ref = jax.vjp(ln_relu, x, g, b)
    out, vjp = jax.vjp(ln_relu_fused, x, g, b)
    np.testing.assert_allclose(out, out_ref, rtol=1e-5, atol=1e-6)
    for got, want in zip(vjp(dy), vjp_ref(dy)):
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5)


@pytest.mark.slow  # a one-off question whose answer benchmarks/README.md records
def test_handwritten_runs_unrolled_seeds():
    from benchmarks.handwritten import run

    assert run(seeds=2, mode="unrolled", calls=2, reps=1) > 0


@pytest.mark.slow  # one of the suite's longest (1-5 min on 2 busy cores); -m slow runs it
def test_device_check_runs_on_a_cpu_with_a_tiny_budget(tmp_path):
    """The GPU check script itself, at a tiny budget: every section of its one results file is there."""
    from benchmarks import device_check

    out = tmp_path / "device.jsonl"
    report = device_check.main(["--quick", "--out", str(out)])
    meta, *cases = [json.loads(line) for line in out.read_text().splitlines()]
    assert cases == report["cases"] and meta["meta"] == {k: v for k, v in report.items() if k != "cases"}
    assert set(report["matmul_tflops"]) == {"highest", "default"} and report["matmul_tflops"]["highest"] > 0
    cases = {(c["algo"], c["seeds"]) for c in report["cases"]}
    assert cases == {("td3bc", 1), ("td3bc", 2), ("edac", 1), ("edac", 2)}
    for c in report["cases"]:
        assert c["updates_per_s"] > 0 and c["finite"] and "pct_of_fp32_matmul" in c and "peak_memory_bytes" in c


ONLINE_KEYS = {"algo", "seeds", "block", "offline_updates_per_s", "online_env_steps_per_s", "pct_of_offline",
               "split_us_per_step", "split_pct", "host_us_per_step", "scan_updates_per_s", "compiles_in_timed_blocks"}


@pytest.mark.slow  # three compilations and 1,500 updates: ~50 s on a loaded core
def test_online_quick_json_reports_the_split_and_no_compilation_per_block(capsys, tmp_path):
    from benchmarks import online
    from offrl_jax.online import loop

    real = {n: getattr(loop, n) for n in ("collect", "insert", "exploration_policy", "MemberEnvs", "device_rows")}
    out = tmp_path / "online.jsonl"
    results = online.main(["--quick", "--json", "--out", str(out)])
    (record,) = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.strip()]
    assert record == results[0] and ONLINE_KEYS <= record.keys()
    assert (record["algo"], record["seeds"], record["block"]) == ("td3bc", 1, 100)
    assert set(record["split_us_per_step"]) == set(record["split_pct"]) == set(online.PIECES)
    assert record["compiles_in_timed_blocks"] == 0  # nothing is recompiled per block
    assert record["online_env_steps_per_s"] > 0 and record["offline_updates_per_s"] > 0
    assert {n: getattr(loop, n) for n in real} == real  # the timing shims are gone
    meta, saved = [json.loads(line) for line in out.read_text().splitlines()]
    assert "command" in meta["meta"] and saved == record


@pytest.mark.parametrize("args, said", [
    (["--quick", "--seeds", "2"], "takes no --seeds"),
    (["--steps", "1500", "--block", "1000"], "multiple of --block"),
    (["--steps", "1000", "--block", "1000"], "at least 2 blocks"),
    (["--algo", "td3bc", "--block", "999", "--steps", "1998"], "policy delay"),
    (["--algo", "bc"], "--algo"),
])
def test_online_benchmark_refuses_bad_sizes_in_one_line(capsys, args, said):
    from benchmarks.online import main

    assert said in _refused(capsys, main, args)


@pytest.mark.slow  # two fresh JAX processes; the answer is in benchmarks/README.md
def test_scaling_runs_its_cases_at_a_tiny_size(capsys):
    from benchmarks.scaling import main

    assert main(["--json", "--seeds", "2", "--cases", "2processes", "--updates", "4", "--chunks", "1"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.strip()]
    assert [(r["case"], r["seeds"], r["processes"]) for r in rows] == [("2processes", 2, 2)]
    assert all(r["updates_per_s"] > 0 for r in rows)


UNIFLORAL_KEYS = {"ours_updates_per_s", "unifloral_updates_per_s", "ratio", "pairs", "layer_norm", "transitions",
                  "updates_per_chunk", "xla_flags", "cores", "jax"}


def test_unifloral_against_a_checkout_with_a_tiny_budget(capsys):
    """benchmarks.unifloral end to end: needs distrax and a unifloral checkout named by UNIFLORAL_PATH."""
    import os
    from pathlib import Path

    pytest.importorskip("distrax")
    path = os.environ.get("UNIFLORAL_PATH")
    if not path or not (Path(path) / "algorithms" / "td3_bc.py").is_file():
        pytest.skip("set UNIFLORAL_PATH to a checkout of github.com/EmptyJackson/unifloral")
    from benchmarks.unifloral import main

    flags = os.environ.get("XLA_FLAGS")
    result = main(["--unifloral", path, "--transitions", "2000", "--updates", "20", "--pairs", "1", "--json"])
    assert os.environ.get("XLA_FLAGS") == flags  # their import sets XLA_FLAGS; the benchmark puts ours back
    (line,) = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.strip()]
    assert UNIFLORAL_KEYS <= line.keys() and line == result
    assert line["pairs"] == 1 and line["layer_norm"] and line["updates_per_chunk"] == 20
    assert line["ours_updates_per_s"] > 0 and line["unifloral_updates_per_s"] > 0


def test_unifloral_bad_checkout_is_one_line_and_exit_2(capsys, tmp_path, monkeypatch):
    import importlib.util

    from benchmarks.unifloral import main

    with pytest.raises(SystemExit) as exit_:
        main(["--unifloral", str(tmp_path / "nowhere")])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "algorithms/td3_bc.py" in err[0]

    (tmp_path / "algorithms").mkdir()
    (tmp_path / "algorithms" / "td3_bc.py").write_text("")
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "distrax" else find_spec(name, *a))
    with pytest.raises(SystemExit) as exit_:
        main(["--unifloral", str(tmp_path)])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install distrax" in err[0]


def test_profile_counts_a_matmuls_flops_from_the_optimised_hlo():
    import jax
    import jax.numpy as jnp

    from benchmarks.profile import dot_flops, parse_hlo, part_of

    text = jax.jit(lambda x, w: jnp.tanh(x @ w)).lower(jnp.ones((4, 8)), jnp.ones((8, 16))).compile().as_text()
    hlo = parse_hlo(text)
    entry = [name for name, ins in hlo.items() if ins["computation"].startswith("main")]  # the ops a trace shows
    matmuls = [name for name in entry if part_of(hlo, name) == "matmul"]
    assert matmuls and sum(dot_flops(hlo, n) for n in matmuls) == 2 * 4 * 8 * 16


@pytest.mark.slow  # a profiler trace; the answer is in benchmarks/README.md
def test_profile_attributes_a_td3bc_update(capsys):
    from benchmarks.profile import main

    assert main(["--updates", "20", "--transitions", "2000", "--json"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    parts = {r["part"]: r for r in result["parts"]}
    assert {"matmul", "layernorm"} <= set(parts)
    assert abs(sum(r["share"] for r in result["parts"]) - 1) < 1e-6
    assert parts["matmul"]["gflops"] > 0 and result["updates"] == 20


def _refused(capsys, main, argv) -> str:
    """`main(argv)` stops while its flags are checked: exit 2 and one `error:` line, nothing on stdout."""
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert exit_.value.code == 2 and len(err) == 1 and err[0].startswith("error: "), captured.err
    assert not captured.out.strip()
    return err[0]


def _mains():
    from benchmarks import device_check, memory, online, profile, throughput

    return {"throughput": (throughput.main, ["--quick"]), "memory": (memory.main, ["--transitions", "1000"]),
            "profile": (profile.main, ["--updates", "2"]), "device_check": (device_check.main, ["--quick"]),
            "online": (online.main, ["--quick"])}


@pytest.mark.parametrize("name", ["throughput", "memory", "profile", "device_check", "online"])
@pytest.mark.parametrize("saved", [b"a user's notes\n", b'{"a": 1}\n[1, 2]\n', b'{"a": 1}\n{"b"', b"\xff\xfe\x00"])
def test_out_refuses_a_file_that_is_not_json_lines_and_leaves_it(capsys, tmp_path, name, saved):
    main, argv = _mains()[name]
    out = tmp_path / "notes.txt"
    out.write_bytes(saved)
    assert "not a results file" in _refused(capsys, main, [*argv, "--out", str(out)])
    assert out.read_bytes() == saved
    assert [f.name for f in tmp_path.iterdir()] == ["notes.txt"]


@pytest.mark.parametrize("name", ["throughput", "memory", "profile", "device_check", "online"])
def test_out_refuses_an_unusable_place_before_any_work(capsys, tmp_path, name):
    main, argv = _mains()[name]
    (tmp_path / "a-file").write_text("kept")
    for out, said in (("", "--out needs a name"), (str(tmp_path), "is a directory"),
                      (str(tmp_path / "a-file" / "x" / "y.jsonl"), "a-file")):
        assert said in _refused(capsys, main, [*argv, "--out", out])
    assert (tmp_path / "a-file").read_text() == "kept" and len(list(tmp_path.iterdir())) == 1


def test_results_path_names_and_markdown_of_an_appended_file(capsys, tmp_path, monkeypatch):
    from benchmarks import common, throughput

    parser = throughput.OneLineParser()
    monkeypatch.setattr(common, "RESULTS_DIR", tmp_path / "results")
    assert common.results_path(parser, None) is None
    assert common.results_path(parser, "mine") == tmp_path / "results" / "mine.jsonl"
    assert common.results_path(parser, "mine.jsonl") == tmp_path / "results" / "mine.jsonl"  # not .jsonl.jsonl
    assert common.results_path(parser, str(tmp_path / "x" / "y")) == tmp_path / "x" / "y"
    assert not (tmp_path / "results").exists() and not (tmp_path / "x").exists()  # checked, nothing made

    row = {"algo": "bc", "phase": "bc", "num_critics": 2, "seeds": 1, "updates_per_s": 10.0, "compile_s": 1.0,
           "gflop_per_update": 0.1, "achieved_gflops": 1.0, "peak_gflops": 10.0, "pct_of_peak": 10.0, "load1": 0.5}
    out = tmp_path / "two-runs.jsonl"
    for run in ("first", "second"):
        meta = {"command": f"the {run} run", "date": "today", "machine": "this one", "load_avg": [0.5]}
        common.append_results(common.results_path(parser, str(out)), [{"meta": meta}, row])
    assert throughput.main(["--markdown", str(out)]) == [row, row]
    text = capsys.readouterr().out
    assert text.count("| algo |") == 2 and "the first run" in text and "the second run" in text


@pytest.mark.parametrize("module, args, flag", [
    ("memory", ["--seeds", "0"], "--seeds"),
    ("memory", ["--seeds", "1", "-1"], "--seeds"),
    ("memory", ["--transitions", "-5"], "--transitions"),
    ("handwritten", ["--seeds", "0"], "--seeds"),
    ("handwritten", ["--seeds", "-3", "--calls", "0", "--reps", "0"], "--seeds"),
    ("handwritten", ["--calls", "0"], "--calls"),
    ("handwritten", ["--reps", "1.5"], "--reps"),
    ("handwritten", ["--mode", "single", "--seeds", "2"], "--mode single"),
    ("pytorch", ["--threads", "-1"], "--threads"),
    ("pytorch", ["--threads", "0"], "--threads"),
    ("pytorch", ["--reps", "-1"], "--reps"),
    ("pytorch", ["--algo"], "--algo"),
    ("scaling", ["--process-id", "-1"], "--process-id"),
])
def test_benchmark_refuses_a_bad_number_in_one_line(capsys, module, args, flag):
    import importlib

    if module == "pytorch":
        pytest.importorskip("torch")
    main = importlib.import_module(f"benchmarks.{module}").main
    assert flag in _refused(capsys, main, args)


@pytest.mark.parametrize("module, args", [
    ("memory", ["--seeds", "0"]),
    ("handwritten", ["--calls", "0"]),
    ("pytorch", ["--threads", "-1"]),
])
def test_benchmark_command_bad_number_is_one_line_and_exit_2(tmp_path, module, args):

    if module == "pytorch":
        pytest.importorskip("torch")
    result = run_module(f"benchmarks.{module}", *args)
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith("error: ") and not result.stdout


def test_pytorch_benchmark_usage_names_the_module(capsys):
    pytest.importorskip("torch")
    from benchmarks.pytorch import main

    with pytest.raises(SystemExit):
        main(["--help"])
    assert capsys.readouterr().out.startswith("usage: benchmarks.pytorch ")
