#!/bin/sh
# Seeds the corpora of both fuzz targets (load, solve) from the example models.
# Run from anywhere; existing corpus entries are kept.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
for target in load solve; do
    mkdir -p "$here/corpus/$target"
    for f in "$here"/../models/*.hyb; do
        cp "$f" "$here/corpus/$target/$(basename "$f")"
    done
done
echo "seeded $(ls "$here/corpus/load" | wc -l) files into corpus/load and corpus/solve"
