#!/usr/bin/env bash
# Crash-safety test of recordings: starts a real `tofcam record`, kills it with SIGKILL mid-run,
# and checks that the file reads back with exactly the frames the recorder had reported as on disk
# (plus at most the one in flight when it died) and that they are bit-identical to the source.
#
# Usage: scripts/kill_recorder_test.sh <tofcam binary> [source dir]
# The source is the ADI raw depth/IR sample (tests/data/real), looped; every recorded frame is
# therefore the same image, which makes the bit-exact check a byte comparison of exported PNGs.
set -euo pipefail
tofcam=$(realpath "$1")
src_dir=${2:-$(dirname "$0")/..}
depth=$(realpath "$src_dir/tests/data/real/adi_adtf3175/out_depth_.bin")
work=$(mktemp -d /tmp/tofcam_kill_test.XXXXXX)
recorder=""
cleanup() {
  if [ -n "$recorder" ]; then kill -9 "$recorder" 2>/dev/null || true; fi
  rm -rf "$work"
}
trap cleanup EXIT

# Reference: the source frame exported once from a clean recording.
"$tofcam" record --camera "import:adi-raw:$depth" --frames 1 --out "$work/ref.h5" 2>/dev/null
"$tofcam" export --in "$work/ref.h5" --out "$work/ref" --format png >/dev/null
ref_png="$work/ref/frame_000000_distance.png"

round=0
for delay in 1.3 2.2 3.1; do
  round=$((round + 1))
  rec="$work/rec$round.h5"
  log="$work/rec$round.log"
  "$tofcam" record --camera "import:adi-raw:$depth" --loop --frames 1000000 --compression 1 \
    --progress-every 1 --out "$rec" 2>"$log" &
  recorder=$!
  sleep "$delay"
  kill -9 "$recorder"
  wait "$recorder" 2>/dev/null || true
  recorder=""
  # Frames the recorder had reported as on disk before it died (a progress line per frame, written
  # after the frame's flush): all of them must survive, plus at most the frame in flight.
  reported=$(grep -o '^record: [0-9]*' "$log" | tail -n 1 | grep -o '[0-9]*$' || echo 0)
  # Export frame 0 and every frame from the last reported one on: the tail is where a torn
  # write would show, and --first fails if fewer frames than reported survived.
  first=$((reported > 0 ? reported - 1 : 0))
  out="$work/out$round"
  if ! summary=$("$tofcam" export --in "$rec" --out "$out" --format png --first "$first" 2>&1) ||
     ! "$tofcam" export --in "$rec" --out "$out" --format png --count 1 >/dev/null 2>&1; then
    echo "kill test round $round: killed recording is unreadable or lost frames: $summary" >&2
    exit 1
  fi
  got=$((first + $(echo "$summary" | grep -o 'wrote [0-9]*' | grep -o '[0-9]*')))
  if [ "$got" -lt 1 ] || [ "$got" -lt "$reported" ] || [ "$got" -gt $((reported + 1)) ]; then
    echo "kill test round $round: $got frames readable, recorder had reported $reported" >&2
    exit 1
  fi
  for f in "$out"/*_distance.png; do
    if ! cmp -s "$f" "$ref_png"; then
      echo "kill test round $round: $(basename "$f") differs from the source frame" >&2
      exit 1
    fi
  done
  echo "kill test round $round: killed after ${delay}s, $got frames readable and exact" \
    "(reported before the kill: $reported)"
done
echo "kill test: passed"
