"""Stands in for wandb: prints each evaluation and the q_min / actor_loss epoch means as JSON lines."""
import json, sys, time
T0 = time.time()
def init(**kw): pass
def mark_preempting(): pass
def log(d):
    if "eval/normalized_score_mean" in d:
        print(json.dumps({"epoch": d["epoch"], "score": float(d["eval/normalized_score_mean"]), "t": round(time.time()-T0)}), flush=True)
    else:
        print(json.dumps({k: float(__import__("numpy").asarray(v).reshape(-1)[0]) for k, v in d.items() if "q_min" in k or "actor_loss" in k or k=="epoch"}), flush=True)
