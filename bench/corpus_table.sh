#!/bin/sh
# Prints docs/reliability.md's corpus table from the last test_corpus run: one row per case with each command's
# exit code and the first error message (transfer's, else the first command that failed).
#   ctest --test-dir build -R 'corpus|Corpus' -j2 && bench/corpus_table.sh build
set -eu
results="${1:-build}/tests/corpus/results"
[ -d "$results" ] || { echo "corpus_table.sh: no results in $results (run the corpus tests first)" >&2; exit 1; }
echo "| case | what | info | transfer | synth | measure | resample | preview | convert | message |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for f in "$results"/*.info.tsv; do
  c=$(basename "$f" .info.tsv)
  row="| \`$c\` | $(cut -f5 "$f") |"
  msg=""
  for cmd in info transfer synth measure resample preview convert; do
    line=$(cat "$results/$c.$cmd.tsv")
    code=$(printf '%s' "$line" | cut -f3)
    row="$row $code |"
    m=$(printf '%s' "$line" | cut -f4)
    if [ -n "$m" ] && { [ -z "$msg" ] || [ "$cmd" = transfer ]; }; then msg="$m"; fi
  done
  # Keep the table readable: the first 150 characters of the message, pipes escaped.
  msg=$(printf '%s' "$msg" | cut -c1-150 | sed 's/|/\\|/g')
  echo "$row $msg |"
done
