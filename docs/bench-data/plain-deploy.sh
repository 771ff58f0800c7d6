#!/bin/bash
# Issue 16's plain command line, N tries, as docs/BENCH.md reports it:
#   addedinertia bench-server --port P --realtime   +   addedinertia deploy --bench socket://127.0.0.1:P ... --json
# both at normal priority. Usage (repository root, venv active):
#   docs/bench-data/plain-deploy.sh OUTDIR TRIES [--load N] -- DEPLOY_ARGS...
#   docs/bench-data/plain-deploy.sh out/plain-lqr 3 -- --controller lqr --host-rate-hz 100
#   docs/bench-data/plain-deploy.sh out/plain-policy 3 --load 2 -- --policy agents/policies/reverse_stroke_100hz.onnx --host-rate-hz 100
# --load N keeps N busy processes (one per core) running during the tries. Prints, per try, the
# time, the 1-min load average before and after, and deploy's keys named in issue 16.
set -u
out=$1; tries=$2; shift 2
load=0
if [ "${1:-}" = "--load" ]; then load=$2; shift 2; fi
[ "${1:-}" = "--" ] && shift
mkdir -p "$out"
burners=()
for _ in $(seq 1 "$load"); do python -c "while True: pass" & burners+=($!); done
for k in $(seq 1 "$tries"); do
  port=$((5600 + k))
  addedinertia bench-server --port $port --realtime > "$out/server$k.log" 2>&1 &
  sp=$!
  sleep 2
  echo "# try $k $(date -u +%T) load $(cut -d' ' -f1 /proc/loadavg)"
  addedinertia deploy --bench socket://127.0.0.1:$port "$@" --out "$out/deploy$k" --json \
    | python -c "import json,sys; d=json.load(sys.stdin); print(json.dumps({k: d.get(k) for k in ['status','lambda66','host_rate_hz','deadline_misses','late_segments','samples_lost','host_period_p50_ms','host_period_p99_ms','max_abs_current_sent_A','trip']}))"
  echo "load after $(cut -d' ' -f1 /proc/loadavg)"
  kill $sp; wait $sp 2>/dev/null
done
for b in "${burners[@]}"; do kill "$b"; done
