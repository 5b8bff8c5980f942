#!/usr/bin/env bash
# The claims table of RESULTS.md: every study's tables from its curves, then one row per comparison (no aggregate:
# their arms are several algorithms)
# (python -m experiments.report; extra arguments, e.g. --curves, are passed on).  Run from anywhere.
set -euo pipefail
cd "$(dirname "$0")/.."
runs=(
  results/mujoco_medium/default-v2
  results/mujoco_medium/default-v1
  results/mujoco_medium/default-5seeds
  results/mujoco_medium/300k-alpha2.5
  results/figure2/halfcheetah-td3bc-5seeds
  results/figure2/halfcheetah-td3bc-100k
  results/figure2/hopper-td3bc-500k
  results/figure2/walker2d-td3bc-5seeds
  results/figure2/halfcheetah-edac-gpu-150k
  results/figure2/walker2d-edac-gpu-150k
  results/figure2/hopper-edac
  results/ablation/hopper-td3bc-v2
  results/ablation/hopper-td3bc-5seeds
  results/qtransformer/hopper-td3bc
  results/replay/hopper-medium-replay-td3bc
  results/replay/hopper-full-replay-td3bc
  results/replay/walker2d-full-replay-td3bc
  results/replay/halfcheetah-full-replay-td3bc
  results/replay/halfcheetah-full-replay-td3bc-lam0
  results/lambda/halfcheetah-td3bc
  results/iql/figure2-hopper-v2-5seeds
  results/iql/figure2-hopper-5seeds
  results/iql/figure2-hopper-beta1-5seeds
  results/iql/figure2-walker2d-5seeds
  results/iql/figure2-halfcheetah-5seeds
  results/rebrac/figure2-hopper-v2-5seeds
  results/rebrac/figure2-hopper-5seeds
  results/rebrac/figure2-halfcheetah-5seeds
  results/rebrac/halfcheetah-beta0.01-3seeds
  results/rebrac/figure2-walker2d-5seeds
)
exec python -m experiments.report "${runs[@]}" "$@"
