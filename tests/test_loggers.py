"""Run tracking (`offrl_jax.run.loggers`): what a logger is sent, TensorBoard and wandb (offline) end to end, and the
plain progress lines of --no-progress."""
from __future__ import annotations

import math

import pytest

from offrl_jax.run.loggers import _Logger, make_logger
from offrl_jax.run.runner import run_study
from offrl_jax.run.study import Study, Variant

from .conftest import synthetic_dataset


class Capture(_Logger):
    def __init__(self, seen=None):
        super().__init__(seen or set())
        self.sent = []

    def write(self, scalars, step):
        self.sent.append((step, scalars))


def row(seed, update, score, seconds, **metrics):
    return {"variant": "v", "algo": "td3bc", "seed": seed, "phase": "offline_rl", "update": update,
            "seconds": seconds, "score": score} | metrics


def test_a_logger_gets_each_seed_the_mean_and_the_rate_once():
    log = Capture()
    first = [row(0, 100, 10.0, 2.0, q_mean=1.0), row(1, 100, 20.0, 2.0, q_mean=3.0)]
    log.log(first)
    log.log(first + [row(0, 200, 30.0, 4.0, q_mean=float("nan")), row(1, 200, 50.0, 4.0, q_mean=5.0)])
    assert [step for step, _ in log.sent] == [100, 200]  # rows already sent are not sent again
    step, scalars = log.sent[0]
    assert scalars["v/seed0/score"] == 10.0 and scalars["v/seed1/q_mean"] == 3.0
    assert scalars["v/score"] == 15.0 and scalars["v/q_mean"] == 2.0
    _, later = log.sent[1]
    assert "v/seed0/q_mean" not in later and later["v/q_mean"] == 5.0  # a NaN is left out, not averaged in
    assert later["v/updates_per_s"] == pytest.approx(100 / 2.0)
    assert all(math.isfinite(v) for _, s in log.sent for v in s.values())


def test_rows_already_in_curves_csv_are_not_sent_again_after_a_resume():
    log = Capture(seen={("v", 0, 100)})
    log.log([row(0, 100, 10.0, 2.0), row(0, 200, 20.0, 4.0)])
    assert [step for step, _ in log.sent] == [200]


def tiny(name):
    return Study(name=name, dataset="synthetic", env="hopper", seeds=(0, 1), updates=200, eval_every=100,
                 eval_episodes=1, batch_size=32,
                 variants=(Variant.of("scratch", "td3bc", pretrain="none", hidden=(32, 32)),))


def read_scalars(log_dir) -> dict[str, list[tuple[int, float]]]:
    """Every scalar of the event files in `log_dir` (TFRecord framing: length, its CRC, the event, its CRC)."""
    import struct

    from tensorboardX.proto import event_pb2

    scalars = {}
    for path in sorted(log_dir.glob("events.out.tfevents.*")):
        data, i = path.read_bytes(), 0
        while i < len(data):
            (n,) = struct.unpack("<Q", data[i:i + 8])
            event = event_pb2.Event()
            event.ParseFromString(data[i + 12:i + 12 + n])
            i += 12 + n + 4
            for value in event.summary.value:
                scalars.setdefault(value.tag, []).append((event.step, value.simple_value))
    return scalars


def test_tensorboard_gets_the_scores(tmp_path):
    pytest.importorskip("tensorboardX")
    run_study(tiny("tb"), tmp_path, synthetic_dataset(), progress=False, logger="tensorboard")
    scalars = read_scalars(tmp_path / "tensorboard")
    assert [step for step, _ in scalars["scratch/score"]] == [100, 200]
    assert "scratch/seed1/critic_loss" in scalars and "scratch/updates_per_s" in scalars


def test_wandb_offline_writes_a_run(tmp_path, monkeypatch):
    pytest.importorskip("wandb")
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    run_study(tiny("wb"), tmp_path, synthetic_dataset(), progress=False, logger="wandb")
    runs = list((tmp_path / "wandb").glob("offline-run-*"))
    assert len(runs) == 1 and any(runs[0].glob("*.wandb"))


def test_an_unknown_logger_is_one_line(tmp_path):
    with pytest.raises(ValueError, match="unknown logger 'mlflow'"):
        make_logger("mlflow", tmp_path, tiny("x"), {})


def test_without_a_progress_bar_every_evaluation_is_one_plain_line(tmp_path, capsys):
    run_study(tiny("plain"), tmp_path, synthetic_dataset(), progress=False)
    lines = [line for line in capsys.readouterr().err.splitlines() if "| score" in line]
    assert len(lines) == 2 and lines[0].startswith("[") and "scratch | offline_rl" in lines[0]
