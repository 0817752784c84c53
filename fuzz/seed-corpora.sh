#!/usr/bin/env bash
# Fills fuzz/corpus/TARGET/ with the seeds of fuzz/seeds.txt (the files the stable runs mutate)
# and the LRTF seed (a table of double-gauss-50mm at resolution 8, baked with the current
# build). cli_flags starts from an empty corpus: its bytes only pick flags and values.
set -euo pipefail
cd "$(dirname "$0")/.."
while read -r target path; do
    case "$target" in '' | '#'*) continue ;; esac
    mkdir -p "fuzz/corpus/$target"
    cp "$path" "fuzz/corpus/$target/"
done <fuzz/seeds.txt
mkdir -p fuzz/corpus/lrtf fuzz/corpus/cli_flags
cargo run --release -q -- lrtf bake double-gauss-50mm --resolution 8 -o fuzz/corpus/lrtf/seed.lrtf
echo "seed corpora in fuzz/corpus/"
