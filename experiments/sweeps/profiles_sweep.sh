#!/usr/bin/env bash
# Issue 29's must-show: 500 simulated episodes per shape (a disc, the Husky, a non-rectangular
# polygon) with 0 collisions in filtered modes. Held-out random worlds (seeds 7000-7124, never
# used to tune anything), the goal operator (it steers straight at the goal, through whatever is
# in the way: the filter must stop it), 60 s at most, stalled after 15 s standing still.
# egc, ek-egc, assist and cbf on 125 worlds each, dwa (11-40 ms a call) on the first 25.
# Writes OUT/<shape>-<filter>.jsonl (default docs/profiles-sweep); a rerun skips finished files.
# The table: python experiments/sweeps/profiles_sweep_table.py docs/profiles-sweep
set -u
cd "$(dirname "$0")/../.."
out=${OUT:-docs/profiles-sweep}
mkdir -p "$out"
export PYTHONPATH=common:robot:operator:sim_robot:experiments:.
py=${PYTHON:-.venv/bin/python}
for shape in turtlebot4 husky docs/profiles/pentagon.toml; do
  tag=$(basename "$shape" .toml)
  for f in egc ek-egc assist cbf dwa; do
    n=125; max=60; stall=15
    [ "$f" = dwa ] && { n=25; max=30; stall=10; }
    file=$out/$tag-$f.jsonl
    [ -s "$file" ] && [ "$(wc -l < "$file")" -ge "$n" ] && continue
    "$py" -m egc_app.cli episode --random-worlds "$n" --seed 7000 --operator goal \
      --filter "$f" --profile "$shape" --max-time "$max" --stall-time "$stall" --jobs 1 \
      --out "$file"
  done
done
