"""benchmarks.libraries: its refusals, its pairing and ratio (with a stand-in adapter), ReBRAC's FLOP count; no
timing assertions.  The real adapters need the other libraries' environments (benchmarks/libraries.py, INSTALL)."""
import json
import sys

import pytest

from benchmarks import libraries
from benchmarks.flops import eval_flops, mlp_dims, update_flops
from offrl_jax.algos import make_config


@pytest.mark.parametrize("args, said", [
    (["d3rlpy", "--python", "/nowhere/python"], "not an executable file"),
    (["fql", "--python", sys.executable], "needs --source"),
    (["ajax-rl", "--python", sys.executable, "--source", "."], "--source is for fql"),
    (["d3rlpy", "--python", sys.executable, "--core", "99"], "--core 99"),
    (["mine", "--python", sys.executable], "invalid choice"),
])
def test_refusals_are_one_line_and_exit_2(capsys, args, said):
    with pytest.raises(SystemExit) as exit_:
        libraries.main(args)
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and said in err[0]


def test_pairs_alternate_and_the_ratio_is_ours_over_theirs(capsys, tmp_path, monkeypatch):
    adapter = tmp_path / "stand_in.py"  # their side: prints three repeats, as every adapter does
    adapter.write_text("import json\nfor r in (40.0, 50.0, 45.0):\n"
                       "    print(json.dumps({'critic_updates_per_s': r}))\n")
    monkeypatch.setattr(libraries, "ADAPTERS", tmp_path)
    monkeypatch.setitem(libraries.LIBRARIES, "d3rlpy", libraries.Library("td3bc", adapter.name, 10, "none"))
    calls = []
    monkeypatch.setattr(libraries, "ours", lambda lib, n, core: calls.append(("ours", lib.algo, n)) or 90.0)
    out = tmp_path / "libs.jsonl"
    result = libraries.main(["d3rlpy", "--python", sys.executable, "--pairs", "2", "--transitions", "500",
                             "--json", "--out", str(out)])
    assert calls == [("ours", "td3bc", 500)] * 2
    assert [p["theirs"] for p in result["pairs"]] == [45.0, 45.0]  # the median of the adapter's repeats
    assert result["ratio"] == 2.0 and result["ours_critic_updates_per_s"] == 90.0
    assert json.loads(capsys.readouterr().out) == result == json.loads(out.read_text())


@pytest.mark.parametrize("script, said", [
    ("import sys\nsys.exit('error: no d3rlpy here')\n", "failed (exit 1): error: no d3rlpy here"),
    ("print('{\"rate\": 1}')\n", "printed a line that is not its JSON result (KeyError"),
    ("print('{not json')\n", "printed a line that is not its JSON result (JSONDecodeError"),
])
def test_a_failing_side_is_one_line_and_exit_1(capsys, tmp_path, monkeypatch, script, said):
    adapter = tmp_path / "broken.py"
    adapter.write_text(script)
    monkeypatch.setattr(libraries, "ADAPTERS", tmp_path)
    monkeypatch.setitem(libraries.LIBRARIES, "d3rlpy", libraries.Library("td3bc", adapter.name, 10, "none"))
    monkeypatch.setattr(libraries, "ours", lambda lib, n, core: 90.0)
    with pytest.raises(SystemExit) as exit_:
        libraries.main(["d3rlpy", "--python", sys.executable, "--pairs", "1"])
    message = str(exit_.value.code)
    assert message.startswith("error: theirs (broken.py) ") and said in message and "\n" not in message


def test_rebrac_flops_count_both_critics_in_the_actor_loss():
    config = make_config("rebrac", "hopper")
    h = tuple(config.hidden)
    actor, critic = mlp_dims(11, h, 3), mlp_dims(14, h, 1)
    total, count = update_flops(config, "offline_rl", 11, 3)
    terms = dict(count.terms)
    assert terms["critics fwd + input-grad x2 (actor loss)"] == eval_flops(critic, 256, "input", 2)
    per_critic_step = eval_flops(actor, 256) + eval_flops(critic, 256, copies=2) + eval_flops(critic, 256, "params", 2)
    assert total == (2 * per_critic_step + eval_flops(actor, 256, "params") + eval_flops(critic, 256, "input", 2)) / 2


def test_rebrac_analytic_flops_match_xla_cost_analysis():
    from benchmarks.flops import xla_update_flops
    from offrl_jax.algos import make_algorithm

    config = make_config("rebrac", "hopper")
    algo = make_algorithm(config, 11, 3, 1000)
    phase = next(p for p in algo.phases(11000) if p.name == "offline_rl")
    analytic, _ = update_flops(config, phase.name, 11, 3)
    assert analytic <= xla_update_flops(algo, phase, 11, 3) <= 1.15 * analytic
