"""Stands in for wandb: prints each evaluation (ReBRAC's, and IQL's d4rl_normalized_score) and ReBRAC's q_min /
actor_loss epoch means as JSON lines.  An evaluation of CORL's fine-tuning ReBRAC (which logs no epoch) prints
{"update", "env_step", "score", "t"}: `updates` (counted by run_finetune.py) and gym.py's online env steps; its
metric lines carry their offline_iter / online_iter and the penalties' coefficients.  CORL's Cal-QL
(eval/d4rl_normalized_score, logged at its update count) prints the same evaluation line, then one line of the last
update's metrics (its per-update logs print nothing).  With OFFRL_STOP_AT=N set, the
run ends at its first evaluation at or past N updates (so CORL's IQL keeps its 1M-update learning-rate schedule and
stops where ours does)."""
import json, os, time
import gym
T0 = time.time()
STOP_AT = int(os.environ.get("OFFRL_STOP_AT", "0"))
updates = 0  # gradient updates made so far, where the runner counts them (run_finetune.py)
last = {}  # Cal-QL's last update's metrics and its last online episode's score, printed at its next evaluation
EPISODE = "train/d4rl_normalized_episode_return"
CALQL = ("offline_iter", "online_iter", "average_qf1", "alpha", "policy_loss", "cql_qf1_diff",
         "bound_rate_cql_q1_current_actions", EPISODE)
def init(**kw): pass
def mark_preempting(): pass
class run:
    @staticmethod
    def save(): pass
def log(d, step=None):
    if "bound_rate_cql_q1_current_actions" in d:  # Cal-QL's update: kept, not printed
        episode = last.get(EPISODE)
        last.clear()
        last.update({EPISODE: episode} if episode is not None else {}, **{k: float(d[k]) for k in CALQL if k in d})
    elif "eval/d4rl_normalized_score" in d:
        print(json.dumps({"update": step, "env_step": gym.Env.env_steps,
                          "score": float(d["eval/d4rl_normalized_score"]), "t": round(time.time()-T0)}), flush=True)
        print(json.dumps(last), flush=True)
    elif "eval/normalized_score_mean" in d and "epoch" not in d:
        print(json.dumps({"update": updates, "env_step": gym.Env.env_steps,
                          "score": float(d["eval/normalized_score_mean"]), "t": round(time.time()-T0)}), flush=True)
    elif "eval/normalized_score_mean" in d:
        print(json.dumps({"epoch": d["epoch"], "score": float(d["eval/normalized_score_mean"]), "t": round(time.time()-T0)}), flush=True)
    elif "d4rl_normalized_score" in d:
        print(json.dumps({"update": step, "score": float(d["d4rl_normalized_score"]), "t": round(time.time()-T0)}), flush=True)
        if STOP_AT and step >= STOP_AT:
            raise SystemExit(0)
    elif step is None:
        keep = lambda k: "q_min" in k or "actor_loss" in k or k == "epoch" or k.endswith(("_iter", "bc_coef"))  # noqa: E731
        print(json.dumps({k: float(__import__("numpy").asarray(v).reshape(-1)[0]) for k, v in d.items() if keep(k)}),
              flush=True)
