# session 7, device call 1: set up, start every job in its own process session, then poll
# (a record of what ran on the GPU machine: .xfer/setup.sh pip-installed the carried py3.12 wheels -- mujoco,
# gymnasium, gymnasium-robotics, minari -- and .xfer/g7_poll.sh waited for the jobs and packed runs/g7 into $OUT)
source .xfer/setup.sh
export XLA_PYTHON_CLIENT_PREALLOCATE=false OFFRL_JAX_CACHE=/tmp/offrl_cache
PY=${PY:-python3}
nvidia-smi -L; nproc
if command -v nvidia-cuda-mps-control >/dev/null; then
  nvidia-cuda-mps-control -d && sleep 1
  if timeout 60 $PY -c "import jax, jax.numpy as jnp; print(jax.devices(), float(jnp.ones(3).sum()))"; then echo MPS=on
  else echo quit | nvidia-cuda-mps-control; sleep 1; echo MPS=off; fi
else echo MPS=absent; fi
$PY -c "import jax, flax, optax, mujoco, gymnasium, gymnasium_robotics; print('versions', jax.__version__, flax.__version__, optax.__version__, mujoco.__version__, gymnasium.__version__, jax.devices())"
L=runs/g7/logs; mkdir -p $L
VARIANTS=("BC" "CQL" "TD3+BC" "EDAC" "TD3+BC+CQL" "pre-trained TD3+BC+CQL" "EDAC+BC" "pre-trained EDAC+BC")
tagof() { echo "$1" | sed 's/ /_/g; s/+/p/g'; }
for v in "${VARIANTS[@]}"; do t=$(tagof "$v")
  setsid nohup $PY -m experiments.adroit_door --dataset door-human --variants "$v" --scale 0.1 --seeds 4 --parallel 1 \
    --no-progress --out runs/g7/door-human/$t > $L/dh-$t.log 2>&1 < /dev/null &
done
for e in walker2d halfcheetah; do
  setsid nohup bash -c "JAX_PLATFORMS=cpu $PY -m offrl_jax.datasets generate $e-medium > $L/gen-$e.log 2>&1 || exit 1
    for p in actor+critic none; do t=\${p/+/_}
      $PY -m experiments.figure2 --envs $e --algos edac --pretrain \$p --pretrain-updates 20000 --actor-pretrain-fraction 0.5 \
        --edac-updates 150000 --edac-eval-every 5000 --seeds 3 --parallel 1 --no-progress --out runs/g7/f2-$e-\$t > $L/f2-$e-\$t.log 2>&1 < /dev/null &
    done; wait" > /dev/null 2>&1 < /dev/null &
done
setsid nohup bash -c "$PY -m offrl_jax.datasets generate door-cloned > $L/gen-door-cloned.log 2>&1 || exit 1
  for v in \"\${@}\"; do t=\$(echo \"\$v\" | sed 's/ /_/g; s/+/p/g')
    $PY -m experiments.adroit_door --dataset door-cloned --variants \"\$v\" --scale 0.1 --seeds 4 --parallel 1 \
      --no-progress --out runs/g7/door-cloned/\$t > $L/dc-\$t.log 2>&1 < /dev/null &
  done; wait" _ "${VARIANTS[@]}" > /dev/null 2>&1 < /dev/null &
sleep 5; ps aux | grep -c "[p]ython3 -m"
bash .xfer/g7_poll.sh $((${1:-540} - SECONDS))
