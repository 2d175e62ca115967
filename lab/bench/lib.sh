# Shared by the lab's shell benchmarks (source it).
# Generating a world once:
#   generate WORLD DIR `$L gen world WORLD DIR --seed 1` unless DIR holds a world already;
#                      city-distinct with `--objects $DISTINCT`
# Serving a world on a free port:
#   serve DIR [LOGS]   starts `$H serve DIR`, waits for the URL it prints, and sets $pid and
#                      $url; its stdout and log go to LOGS (default $work)
#   stop               ends it (nothing if none runs)
# A scratch directory for the server's output, removed with the server on exit:
#   scratch            sets $work, and traps EXIT to `stop` and remove it
# A script sets L (to generate) or H (to serve), and calls `stop` from its EXIT trap (`scratch`
# sets one).
pid=

generate() {
  local world=$1 dir=$2
  [ -f "$dir/world.db" ] && return 0
  if [ "$world" = city-distinct ]; then
    "$L" gen world "$world" "$dir" --seed 1 --objects "$DISTINCT" > /dev/null
  else
    "$L" gen world "$world" "$dir" --seed 1 > /dev/null
  fi
}

serve() {
  local logs=${2:-$work}
  "$H" serve "$1" --listen 127.0.0.1:0 > "$logs/serve.out" 2> "$logs/serve.log" &
  pid=$!
  for _ in $(seq 600); do
    if grep -q "^listening on " "$logs/serve.out" 2>/dev/null; then break; fi
    sleep 0.2
  done
  url=$(sed -n 's/^listening on //p' "$logs/serve.out" | head -1)
  [ -n "$url" ] || { echo "horizon serve did not start" >&2; cat "$logs/serve.log" >&2; exit 1; }
  curl -sf "$url/v1/world" > /dev/null
}

stop() {
  if [ -n "$pid" ]; then kill "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; fi
  pid=
}

scratch() {
  work=$(mktemp -d)
  trap 'stop; rm -rf "$work"' EXIT
}
