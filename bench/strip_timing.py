#!/usr/bin/python3
"""JSON lines on stdin without what changes from run to run: times, rates and memory.

Used by bench/identical.sh. A line that is not JSON passes through unchanged."""
import json
import re
import sys

VOLATILE = re.compile(r"(_s|seconds|_time|time|rss|_mb|elapsed|per_frame|s_per_frame|wall|cpu)$")


def clean(v):
    if isinstance(v, dict):
        return {k: clean(x) for k, x in v.items() if not VOLATILE.search(k)}
    if isinstance(v, list):
        return [clean(x) for x in v]
    return v


for line in sys.stdin:
    try:
        print(json.dumps(clean(json.loads(line)), sort_keys=True))
    except ValueError:
        sys.stdout.write(line)
