#!/bin/bash
# One device lease: RGB-D rope push runs (3-step targets, inverse dynamics, 10,000-pair cache, batch 64) on
# CUDA, seeds SEEDS of Indicator+Balance+Filter and plain Indicator in parallel, stopped with SIGTERM (the
# trainers' clean stop) at RUN_S seconds; their metrics and logs go to $OUT/gpu_runs.tar.gz.
# Carry .dev (prepare.sh), .gl and outputs/rope_cache. The image's python3 holds torch.
T0=$(date +%s); RUN_S=${RUN_S:-440}; SEEDS=${SEEDS:-"4 5 6 7"}
el() { echo $(( $(date +%s) - T0 )); }
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site .dev/whl/*.whl || exit 3
cp -r .dev/site/robosuite .dev/stub/av .dev/stub/av-15.1.0.dist-info /tmp/site/
python3 -m pip install -q --no-index --no-deps --no-build-isolation --no-compile --target /tmp/site . \
    > /tmp/pip_self.log 2>&1 || { tail /tmp/pip_self.log; exit 4; }
# experiments.py starts the trainer from python3's own bin folder
X="$(python3 -c 'import sys; print(sys.executable)')"; T="$(dirname "$X")/lerobot-indicator-train"; rm -f "$T"
printf '#!%s\nimport sys\nfrom lerobot_indicator.training.online import main\nif __name__ == "__main__":\n    sys.exit(main())\n' \
    "$X" > "$T" && chmod +x "$T" || exit 6
export PYTHONPATH=/tmp/site MUJOCO_GL=egl PYTHONUNBUFFERED=1
V=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json; [ -f $V ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$V
nvidia-smi -L; nproc; lscpu | grep "Model name"; echo "setup $(el)s"
mkdir -p logs; python3 docs/results/experiments_rope_rgbd/gpu_lease/probe.py > logs/probe.log 2>&1; rc=$?
grep -v -i "warning\|robosuite\|macro" logs/probe.log; [ $rc -eq 0 ] || exit 5
E="--extra_args=[--env.cache_path=outputs/rope_cache/rope_push_10k.npz,--online.batch_size=64]"
for s in $SEEDS; do for m in indicator_balance_filter indicator; do
  python3 -m benchmarks.experiments.run --tasks='[rope_rgbd]' --methods="[${m}_n3_inverse_dynamics]" --seeds="[$s]" \
    --steps=20000 --device=cuda --n_envs=4 --out=outputs/gpu/agg_${m}_s$s --runs_dir=outputs/gpu/runs "$E" \
    > logs/${m}_s$s.log 2>&1 &
done; done
# fail fast (the lease is short): every run must have logged its first cycle after 100 s
sleep 100; n=$(ls outputs/gpu/runs/rope_rgbd/*/seed_*/metrics.jsonl 2>/dev/null | wc -l); echo "runs logging: $n"
[ "$n" -eq 0 ] && { tr '\r' '\n' < "$(ls logs/*_s*.log | head -1)" | tail -n 20; pkill -TERM -f experiments.py; exit 7; }
nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv; uptime
while [ "$(el)" -lt "$RUN_S" ]; do sleep 10; done
pkill -TERM -f experiments.py  # a job started with & ignores SIGINT (POSIX)
for _ in $(seq 20); do pgrep -f "experiments.py|lerobot-indicator-train" > /dev/null || break; sleep 1; done
pkill -9 -f "experiments.py|lerobot-indicator-train"
for f in logs/*.log; do echo "$f: $(tail -c 200 "$f" | tr '\r' '\n' | tail -1)"; done
tar czf "$OUT/gpu_runs.tar.gz" logs outputs/gpu/runs/rope_rgbd/*/seed_*/metrics.jsonl; echo "done $(el)s"
