#!/usr/bin/env bash
# Load on the REST service with wrk, beside a bare Pistache endpoint that
# answers a constant (bench/bare_pistache.cpp), in the same run:
#   1. the yardstick, health, job status (session + SQLite read), a 64 KiB
#      Range of a video;
#   2. 50 connections downloading random Ranges of a video while a job runs;
#   3. job submission with its prediction, on a second server with no workers
#      (each request a new scene, so none is answered from an earlier result),
#      by CONNECTIONS clients at once and by one.
# Prints Markdown tables for docs/benchmarks.md. Bounded: each wrk run lasts
# DURATION seconds; the servers are stopped at the end, pass or fail.
#
#   bash bench/service_load.sh [BUILD_DIR] [DURATION_S] [CONNECTIONS] [SERVER_THREADS]
set -euo pipefail
build=${1:-build}
duration=${2:-10}
connections=${3:-32}
threads=${4:-2}
bin="$build/app/collidoscope"
bare="$build/bench/bare_pistache"
command -v wrk >/dev/null || { echo "service_load: wrk is not installed (scripts/install-deps.sh)"; exit 1; }
for f in "$bin" "$bare"; do [ -x "$f" ] || { echo "service_load: no $f (build first)"; exit 1; }; done

work=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT

# Starts a server in the background; its base URL once it prints it.
wait_url() {  # LOG PATTERN
  for _ in $(seq 200); do
    local u
    u=$(grep -o "$2" "$1" | head -1 || true)
    [ -n "$u" ] && { echo "$u"; return; }
    sleep 0.05
  done
  cat "$1" >&2
  exit 1
}
"$bare" "$threads" >"$work/bare.log" 2>&1 &
pids+=($!)
bare_url="http://127.0.0.1:$(wait_url "$work/bare.log" 'listening on [0-9]*' | awk '{print $3}')"
"$bin" serve --port 0 --threads "$threads" --data "$work/var" --web "" --job-threads 1 >"$work/serve.log" 2>&1 &
pids+=($!)
base=$(wait_url "$work/serve.log" 'http://127.0.0.1:[0-9]*')
"$bin" serve --port 0 --threads "$threads" --data "$work/var2" --web "" --workers 0 --max-queued 10000 \
  >"$work/serve2.log" 2>&1 &
pids+=($!)
base2=$(wait_url "$work/serve2.log" 'http://127.0.0.1:[0-9]*')

json() { python3 -c "import json,sys; print(json.load(sys.stdin)$1)"; }
sign_in() {  # BASE NAME -> token
  curl -sf -X POST "$1/api/v1/accounts" -d "{\"name\":\"$2\",\"password\":\"load-password-1\"}" >/dev/null
  curl -sf -X POST "$1/api/v1/sessions" -d "{\"name\":\"$2\",\"password\":\"load-password-1\"}" | json '["token"]'
}
token=$(sign_in "$base" load)
token2=$(sign_in "$base2" load)
token3=$(sign_in "$base2" load-one)  # the one-client row's jobs, apart from the queue limit of the first
auth="Authorization: Bearer $token"
scene() {  # PARTICLES DURATION
  echo "{\"scene\":{\"wall\":\"wall1\",\"particles\":{\"count\":$1,\"radius\":0.5},\"placement\":{\"kind\":\"pour\"},\"duration\":$2,\"fps\":24},\"render\":{\"width\":640,\"height\":360,\"formats\":[\"mp4\"]}}"
}
wait_done() {  # JOB
  local state=""
  for _ in $(seq 1500); do
    state=$(curl -sf -H "$auth" "$base/api/v1/jobs/$1" | json '["state"]')
    case $state in done) return 0 ;; failed|cancelled) echo "service_load: job $1 $state" >&2; exit 1 ;; esac
    sleep 0.2
  done
  echo "service_load: job $1 did not finish" >&2
  exit 1
}
job=$(curl -sf -X POST -H "$auth" "$base/api/v1/jobs" -d "$(scene 200 1)" | json '["id"]')
wait_done "$job"
video="/api/v1/jobs/$job/files/render/video.mp4"
video_bytes=$(curl -sf -H "$auth" "$base$video" | wc -c)

cat >"$work/ranges.lua" <<LUA
-- Random 64 KiB ranges of the video, as a player seeking.
request = function()
  local first = math.random(0, math.max(0, $video_bytes - 65536))
  return wrk.format("GET", "$video", {["Authorization"] = "Bearer $token",
                                       ["Range"] = "bytes=" .. first .. "-" .. (first + 65535)})
end
LUA
submit_lua() {  # TOKEN -> a wrk script submitting, as that user, scenes not seen before
  cat <<LUA
-- Each request a scene not seen before: durations from a per-thread range,
-- 1 s and a few microseconds. Small jobs: the queue they build (10,000 and
-- more) is admitted by its files' disk as well as its memory, and a million
-- particles' jobs (the counts this used to vary) take 1.8 GB of disk each.
local next_id = 1
local counter = 0
setup = function(thread) thread:set("base", next_id * 1000000); next_id = next_id + 1 end
request = function()
  counter = counter + 1
  local body = string.format('{"scene":{"wall":"wall1","particles":{"count":2000,"radius":0.5},'
      .. '"placement":{"kind":"pour"},"duration":%.9f,"fps":24},"render":{"width":160,"height":96}}',
      1 + ((base or 0) + counter) * 1e-9)
  return wrk.format("POST", "/api/v1/jobs", {["Authorization"] = "Bearer $1",
                                              ["Content-Type"] = "application/json"}, body)
end
LUA
}
submit_lua "$token2" >"$work/submit.lua"
submit_lua "$token3" >"$work/submit_one.lua"

# One wrk run as a table row: requests/s, latency percentiles, errors.
row() {
  local name=$1 conns=$2; shift 2
  local out
  out=$(wrk -t "$(( conns < 2 ? conns : 2 ))" -c "$conns" -d "${duration}s" --latency "$@" 2>&1)
  local rps p50 p99 non2xx errors
  rps=$(awk '/Requests\/sec/ {print $2}' <<<"$out")
  p50=$(awk '$1 == "50%" {print $2}' <<<"$out")
  p99=$(awk '$1 == "99%" {print $2}' <<<"$out")
  non2xx=$(awk '/Non-2xx/ {print $NF}' <<<"$out")
  errors=$(sed -n 's/^ *Socket errors: //p' <<<"$out")
  printf '| %s | %s | %s | %s | %s | %s |\n' "$name" "$conns" "$rps" "$p50" "$p99" "${non2xx:-0}${errors:+; $errors}"
}

echo "service_load: $(nproc) CPUs, $threads reactor threads per server, ${duration} s per row, $(wrk -v 2>&1 | head -1 | awk '{print $1, $2}')"
echo
echo "| route | connections | requests/s | p50 | p99 | non-2xx; socket errors |"
echo "|---|---|---|---|---|---|"
row "bare Pistache, constant (yardstick)" "$connections" "$bare_url/"
row "GET /api/v1/health" "$connections" "$base/api/v1/health"
row "GET /api/v1/jobs/{id} (session, SQLite read)" "$connections" -H "$auth" "$base/api/v1/jobs/$job"
row "GET video, Range 64 KiB (206)" "$connections" -H "$auth" -H "Range: bytes=0-65535" "$base$video"
long=$(curl -sf -X POST -H "$auth" "$base/api/v1/jobs" -d "$(scene 3000 4)" | json '["id"]')
sleep 1
row "GET video, random 64 KiB Ranges, while a job runs" 50 -s "$work/ranges.lua" "$base$video"
row "POST /api/v1/jobs (new scene, prediction, queued)" "$connections" -s "$work/submit.lua" "$base2/api/v1/jobs"
row "POST /api/v1/jobs, one client at a time" 1 -s "$work/submit_one.lua" "$base2/api/v1/jobs"
wait_done "$long"
echo
echo "the job that ran during the Range downloads: $(curl -sf -H "$auth" "$base/api/v1/jobs/$long" | json '["state"]')"
