#!/usr/bin/env bash
# Load on the REST service with wrk: a server on 127.0.0.1 (a free port, a
# fresh data folder), one account, one small finished job, then fixed-length
# wrk runs against the routes people hit most. Prints a Markdown table for
# docs/benchmarks.md. Bounded: each run lasts DURATION seconds; the server is
# stopped at the end, pass or fail.
#
#   bash bench/service_load.sh [BUILD_DIR] [DURATION_S] [CONNECTIONS] [SERVER_THREADS]
set -euo pipefail
build=${1:-build}
duration=${2:-10}
connections=${3:-32}
threads=${4:-2}
bin="$build/app/collidoscope"
command -v wrk >/dev/null || { echo "service_load: wrk is not installed (scripts/install-deps.sh)"; exit 1; }
[ -x "$bin" ] || { echo "service_load: no $bin (build first)"; exit 1; }

work=$(mktemp -d)
pid=""
cleanup() { [ -n "$pid" ] && kill "$pid" 2>/dev/null && wait "$pid" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT

"$bin" serve --port 0 --threads "$threads" --data "$work/var" --web "" --job-threads 1 >"$work/serve.log" 2>&1 &
pid=$!
base=""
for _ in $(seq 100); do
  base=$(grep -o 'http://127.0.0.1:[0-9]*' "$work/serve.log" | head -1 || true)
  [ -n "$base" ] && break
  sleep 0.1
done
[ -n "$base" ] || { cat "$work/serve.log"; exit 1; }

json() { python3 -c "import json,sys; print(json.load(sys.stdin)$1)"; }
curl -sf -X POST "$base/api/v1/accounts" -d '{"name":"load","password":"load-password-1"}' >/dev/null
token=$(curl -sf -X POST "$base/api/v1/sessions" -d '{"name":"load","password":"load-password-1"}' | json '["token"]')
auth="Authorization: Bearer $token"
scene='{"scene":{"wall":"wall1","particles":{"count":200,"radius":0.5},"placement":{"kind":"pour"},"duration":1,"fps":24},"render":{"width":640,"height":360,"formats":["mp4"]}}'
job=$(curl -sf -X POST -H "$auth" "$base/api/v1/jobs" -d "$scene" | json '["id"]')
for _ in $(seq 600); do
  state=$(curl -sf -H "$auth" "$base/api/v1/jobs/$job" | json '["state"]')
  [ "$state" = done ] && break
  [ "$state" = failed ] && { echo "service_load: the job failed"; exit 1; }
  sleep 0.2
done
[ "$state" = done ] || { echo "service_load: the job did not finish"; exit 1; }
video="/api/v1/jobs/$job/files/render/video.mp4"
video_bytes=$(curl -sf -H "$auth" "$base$video" | wc -c)

cat >"$work/predict.lua" <<LUA
wrk.method = "POST"
wrk.body = '$scene'
wrk.headers["Content-Type"] = "application/json"
wrk.headers["Authorization"] = "Bearer $token"
LUA

# One wrk run: its requests/s, latency percentiles and errors, as a table row.
run() {
  local name=$1; shift
  local out
  out=$(wrk -t 2 -c "$connections" -d "${duration}s" --latency "$@" 2>&1)
  local rps p50 p99 non2xx errors
  rps=$(awk '/Requests\/sec/ {print $2}' <<<"$out")
  p50=$(awk '$1 == "50%" {print $2}' <<<"$out")
  p99=$(awk '$1 == "99%" {print $2}' <<<"$out")
  non2xx=$(awk '/Non-2xx/ {print $NF}' <<<"$out")
  errors=$(awk '/Socket errors/ {print $0}' <<<"$out" | sed 's/^ *Socket errors: //')
  printf '| %s | %s | %s | %s | %s |\n' "$name" "$rps" "$p50" "$p99" "${non2xx:-0}${errors:+; $errors}"
}

echo "service_load: $(nproc) CPUs, $threads server threads, $connections connections, ${duration} s per route, wrk $(wrk -v 2>&1 | head -1 | awk '{print $2}')"
echo
echo "| route | requests/s | p50 | p99 | non-2xx; socket errors |"
echo "|---|---|---|---|---|"
run "GET /api/v1/health" "$base/api/v1/health"
run "GET /api/v1/jobs/{id} (session, SQLite read)" -H "$auth" "$base/api/v1/jobs/$job"
run "GET video, Range 64 KiB (206)" -H "$auth" -H "Range: bytes=0-65535" "$base$video"
run "GET video whole ($video_bytes bytes)" -H "$auth" "$base$video"
run "POST /api/v1/predict (scene assessed)" -s "$work/predict.lua" "$base/api/v1/predict"
kill "$pid"; wait "$pid" 2>/dev/null || true; pid=""
