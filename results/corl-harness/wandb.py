"""Stands in for wandb: prints each evaluation (ReBRAC's, and IQL's d4rl_normalized_score) and ReBRAC's q_min /
actor_loss epoch means as JSON lines. With OFFRL_STOP_AT=N set, the run ends at its first evaluation at or past N
updates (so CORL's IQL keeps its 1M-update learning-rate schedule and stops where ours does)."""
import json, os, time
T0 = time.time()
STOP_AT = int(os.environ.get("OFFRL_STOP_AT", "0"))
def init(**kw): pass
def mark_preempting(): pass
class run:
    @staticmethod
    def save(): pass
def log(d, step=None):
    if "eval/normalized_score_mean" in d:
        print(json.dumps({"epoch": d["epoch"], "score": float(d["eval/normalized_score_mean"]), "t": round(time.time()-T0)}), flush=True)
    elif "d4rl_normalized_score" in d:
        print(json.dumps({"update": step, "score": float(d["d4rl_normalized_score"]), "t": round(time.time()-T0)}), flush=True)
        if STOP_AT and step >= STOP_AT:
            raise SystemExit(0)
    elif step is None:
        print(json.dumps({k: float(__import__("numpy").asarray(v).reshape(-1)[0]) for k, v in d.items() if "q_min" in k or "actor_loss" in k or k=="epoch"}), flush=True)
