#!/usr/bin/env bash
# The upload unit end to end: systemd/pandarcap-upload@.service's own command line (read from the
# unit file, its Environment= defaults and a NAME-upload.conf applied as systemd would) moves an
# instance's recordings to an SFTP server this test starts (rclone's own `serve sftp`, on
# 127.0.0.1), and:
#   1. the link is cut mid-upload (the server killed): the run fails, and no file has left the
#      vehicle that has not arrived whole (checked all through the run, by checksum);
#   2. the server back, the next run moves every finished file: each arrives exactly once and
#      whole, and nothing else arrives (tests/upload/names.txt: what moves and what stays), a
#      file finished during the first run included; one finished just now waits (--min-age);
#   3. a remote that refuses one file: that file stays on the vehicle, the others move, and the
#      run fails (the timer's next run tries again);
#   4. an output directory that is not there: the run fails, nothing is touched.
# Usage: check_upload_unit.sh UNIT_FILE SOURCE_DIR   (UNIT_FILE: pandarcap-upload@.service as built)
set -euo pipefail
unit=$1
source_dir=$(cd "$2" && pwd)
fail() {
  echo "FAIL: $*" >&2
  exit 1
}
command -v rclone >/dev/null || fail "rclone not found (Debian package rclone: .ci/install-deps)"

work=$(mktemp -d)
server_pid=
stop_server() { { kill -9 "$server_pid" && wait "$server_pid"; } 2>/dev/null || true; }
cleanup() {
  [ -z "$server_pid" ] || stop_server
  rm -rf "$work"
}
trap cleanup EXIT
# rclone keeps its server keys and cache under HOME: the test's own.
export HOME=$work/home
mkdir -p "$HOME"

# --- The unit's command line, as systemd builds it for pandarcap-upload@front --------------------
# Continuation lines joined; then the Environment= defaults, then the EnvironmentFile (it wins).
# The command is split into words by bash, which reads the unit's quoting as systemd does as long
# as it holds nothing else: checked first, so a unit this cannot read fails here, not later.
unit_text=$(sed -e ':a' -e '/\\$/N; s/\\\n//; ta' "$unit")
exec_start=$(sed -n 's/^ExecStart=//p' <<<"$unit_text")
[ "$(wc -l <<<"$exec_start")" = 1 ] || fail "one ExecStart= expected in $unit"
instance_value() { # the specifiers this test knows: %i and %%; any other fails
  local value=${1//%i/front}
  value=${value//%%/%}
  [[ $value != *%* ]] || fail "a specifier this test does not know in: $1"
  printf '%s' "$value"
}
exec_start=$(instance_value "$exec_start")
unquoted=$(sed -e 's/"[^"]*"//g' <<<"$exec_start")
[[ $unquoted =~ ^[A-Za-z0-9_./:,=\ -]*$ ]] || fail "ExecStart has shell-special text outside quotes: $unquoted"
quoted=$(grep -o '"[^"]*"' <<<"$exec_start" | sed -e 's/\${[A-Z_][A-Z0-9_]*}//g')
if grep -q '[$`\\!]' <<<"$quoted"; then fail "ExecStart quotes more than \${NAME}: $quoted"; fi

unit_environment=()
while IFS= read -r line; do
  value=$(instance_value "${line#Environment=}")
  [[ $value =~ ^[A-Z_][A-Z0-9_]*=[^\ \"]*$ ]] || fail "Environment= this test cannot read: $line"
  unit_environment+=("$value")
done < <(grep '^Environment=' <<<"$unit_text")

# Without a config file (the remote is the .conf's variables): an SFTP remote would otherwise
# save what it detects into one, here somewhere outside the test's directory.
printf '%s\n' "${unit_environment[@]}" | grep -qx 'RCLONE_CONFIG=' ||
  fail "the unit names an rclone config file (RCLONE_CONFIG); it runs without one"

conf=$work/front-upload.conf
run_unit() { # run_unit LOG: the unit's command, in the unit's environment; its exit status
  (
    for value in "${unit_environment[@]}"; do export "${value?}"; done
    while IFS= read -r line; do
      [[ $line =~ ^[[:space:]]*(#|$) ]] && continue
      export "${line%%=*}=${line#*=}"
    done <"$conf"
    eval "command=($exec_start)"
    exec "${command[@]}"
  ) >"$1" 2>&1
}

# --- The vehicle: an instance's output directory ---------------------------------------------------
vehicle=$work/vehicle
remote_root=$work/remote
remote=$remote_root/fleet/front
orig=$work/orig
mkdir -p "$vehicle"/{raw,mcap,frames,health} "$remote_root" "$orig"
old=$(($(date +%s) - 3600)) # finished an hour ago
make() { # make PATH BYTES: random bytes, a pristine copy kept, finished an hour ago
  mkdir -p "$(dirname "$vehicle/$1")" "$(dirname "$orig/$1")"
  head -c "$2" /dev/urandom >"$vehicle/$1"
  cp "$vehicle/$1" "$orig/$1"
  touch -d "@$old" "$vehicle/$1"
}
up=()
stays=()
while read -r verdict path; do
  [[ -z $verdict || $verdict == \#* ]] && continue
  make "$path" 3000
  if [ "$verdict" = up ]; then up+=("$path"); else stays+=("$path"); fi
done <"$source_dir/tests/upload/names.txt"
# Recordings large enough that the link can be cut in the middle of one (1 MiB/s below), the
# newest, so they go last (oldest first): once the link is cut, rclone waits out its pacer (2 s)
# for each file it has not started yet, and there are none left by then.
for i in 0 1; do
  path=raw/pandarcap_20261127T230000Z_010$i.pcap.zst
  make "$path" 786432
  touch -d "@$((old + 60))" "$vehicle/$path"
  up+=("$path")
done
# Open while the first run lists the files; finished (renamed into place) while it uploads.
make raw/pandarcap_20261127T230000Z_0200.pcap.zst.part 20000
# Finished a moment ago: --min-age keeps it for a later run.
make raw/pandarcap_20261127T230000Z_0300.pcap.zst 20000
touch "$vehicle/raw/pandarcap_20261127T230000Z_0300.pcap.zst"
echo "vehicle: ${#up[@]} files to upload, ${#stays[@]} to leave, 1 open, 1 just finished"

# --- The remote: rclone's SFTP server on loopback --------------------------------------------------
start_server() { # start_server ADDRESS: sets server_pid and port (waits until it listens)
  rclone serve sftp "$remote_root" --addr "$1" --user vehicle --pass secret \
    >"$work/server.log" 2>&1 &
  server_pid=$!
  for _ in $(seq 200); do
    port=$(sed -n 's/.*SFTP server listening on 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$work/server.log")
    [ -n "$port" ] && return
    kill -0 "$server_pid" 2>/dev/null || break
    sleep 0.05 # until its line says it listens
  done
  cat "$work/server.log" >&2
  fail "rclone serve sftp did not start"
}
start_server 127.0.0.1:0
cat >"$conf" <<EOF
# The test's front-upload.conf: the remote is the SFTP server above.
PANDARCAP_UPLOAD_SOURCE=$vehicle
PANDARCAP_UPLOAD_REMOTE=fleet:fleet/front
PANDARCAP_UPLOAD_MIN_AGE=30s
PANDARCAP_UPLOAD_BWLIMIT=1M
RCLONE_CONFIG_FLEET_TYPE=sftp
RCLONE_CONFIG_FLEET_HOST=127.0.0.1
RCLONE_CONFIG_FLEET_PORT=$port
RCLONE_CONFIG_FLEET_USER=vehicle
RCLONE_CONFIG_FLEET_PASS=$(rclone obscure secret)
RCLONE_CONTIMEOUT=2s
RCLONE_TIMEOUT=5s
RCLONE_RETRIES=1
RCLONE_LOW_LEVEL_RETRIES=1
EOF

# Nothing left the vehicle that has not arrived whole: a file gone from here is on the remote,
# byte for byte (rclone removes it only after its checksum matched).
check_gone_arrived() {
  for path in "${up[@]}"; do
    [ -e "$vehicle/$path" ] && continue
    cmp -s "$orig/$path" "$remote/$path" || fail "$path left the vehicle but is not whole on the remote"
  done
}
# Runs the unit while checking the above; returns its exit status.
run_checked() { # run_checked LOG [ACTION_WHILE_RUNNING]
  run_unit "$1" &
  local pid=$! acted=0
  while kill -0 "$pid" 2>/dev/null; do
    check_gone_arrived
    if [ -n "${2:-}" ] && [ "$acted" = 0 ] && "$2"; then acted=1; fi
    sleep 0.05 # a look every 50 ms: the check, not a synchronisation
  done
  local status=0
  wait "$pid" || status=$?
  check_gone_arrived
  return "$status"
}

# 1. The link is cut while a recording is half across: the server killed.
cut=0
cut_mid_upload() {
  for i in 0 1; do
    f=$remote/raw/pandarcap_20261127T230000Z_010$i.pcap.zst
    size=$(stat -c %s "$f" 2>/dev/null || echo 0)
    if [ "$size" -gt 0 ] && [ "$size" -lt 786432 ]; then
      mv "$vehicle/raw/pandarcap_20261127T230000Z_0200.pcap.zst.part" \
        "$vehicle/raw/pandarcap_20261127T230000Z_0200.pcap.zst"
      stop_server
      cut=1
      echo "cut: the server killed with $f at $size of 786432 bytes"
      return 0
    fi
  done
  return 1
}
status=0
run_checked "$work/run1.log" cut_mid_upload || status=$?
[ "$cut" = 1 ] || { cat "$work/run1.log"; fail "the run ended before the link could be cut"; }
[ "$status" != 0 ] || { cat "$work/run1.log"; fail "the run cut off mid-upload exited 0"; }
left=0
for path in "${up[@]}"; do [ -e "$vehicle/$path" ] && left=$((left + 1)); done
[ "$left" -gt 0 ] || fail "the cut came after everything was uploaded: nothing was tested"
echo "run 1 (link cut): exit $status, $left of ${#up[@]} files still on the vehicle, none lost"

# 2. The server back on the same port: the next run moves the rest (at full speed).
start_server "127.0.0.1:$port"
echo "PANDARCAP_UPLOAD_BWLIMIT=off" >>"$conf"
touch -d "@$old" "$vehicle/raw/pandarcap_20261127T230000Z_0200.pcap.zst" # finished an hour ago
cp "$vehicle/raw/pandarcap_20261127T230000Z_0200.pcap.zst" "$orig/raw/"
up+=(raw/pandarcap_20261127T230000Z_0200.pcap.zst)
status=0
run_checked "$work/run2.log" || status=$?
[ "$status" = 0 ] || { cat "$work/run2.log"; fail "the run after the link came back exited $status"; }
arrived=$(cd "$remote" && find . -type f | sed 's|^\./||' | sort)
expected=$(printf '%s\n' "${up[@]}" | sort)
[ "$arrived" = "$expected" ] || fail "the remote holds other files than those to upload:
$(diff <(echo "$expected") <(echo "$arrived"))"
for path in "${up[@]}"; do
  cmp -s "$orig/$path" "$remote/$path" || fail "$path did not arrive whole"
  [ ! -e "$vehicle/$path" ] || fail "$path arrived but is still on the vehicle"
done
for path in "${stays[@]}"; do
  cmp -s "$orig/$path" "$vehicle/$path" || fail "$path was moved or changed: it is not to be uploaded"
done
[ -e "$vehicle/raw/pandarcap_20261127T230000Z_0300.pcap.zst" ] || fail "a file finished just now left"
echo "run 2 (link back): every one of ${#up[@]} files arrived once and whole; ${#stays[@]} stayed"

# 3. A remote that refuses one file (a directory in its place there): it stays here, the
# others move, the run fails.
make raw/pandarcap_20261127T230000Z_0400.pcap.zst 5000
make raw/pandarcap_20261127T230000Z_0401.pcap.zst 5000
mkdir -p "$remote/raw/pandarcap_20261127T230000Z_0400.pcap.zst"
up+=(raw/pandarcap_20261127T230000Z_0401.pcap.zst)
status=0
run_checked "$work/run3.log" || status=$?
[ "$status" != 0 ] || { cat "$work/run3.log"; fail "a run with a refused file exited 0"; }
cmp -s "$orig/raw/pandarcap_20261127T230000Z_0400.pcap.zst" \
  "$vehicle/raw/pandarcap_20261127T230000Z_0400.pcap.zst" || fail "the refused file left the vehicle"
[ ! -e "$vehicle/raw/pandarcap_20261127T230000Z_0401.pcap.zst" ] || fail "a file beside it did not move"
echo "run 3 (one file refused): exit $status, the refused file still here, the other moved"

# 4. The output directory is not there (a disk not mounted): the run fails, touching nothing.
echo "PANDARCAP_UPLOAD_SOURCE=$work/not-mounted" >>"$conf"
before=$(cd "$remote_root" && find . | sort)
status=0
run_unit "$work/run4.log" || status=$?
[ "$status" != 0 ] || fail "a run from a missing directory exited 0"
[ "$(cd "$remote_root" && find . | sort)" = "$before" ] || fail "a run from a missing directory changed the remote"
echo "run 4 (no output directory): exit $status, nothing touched"
echo "upload unit: PASS"
