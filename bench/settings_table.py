#!/usr/bin/python3
"""A markdown table of a command's second-tier settings, from its own --help-all and --print-settings.

    /usr/bin/python3 bench/settings_table.py build/tools/vdbturb transfer

Used to keep the settings tables of docs/*.md in step with the code."""
import re
import subprocess
import sys

exe, cmd = sys.argv[1], sys.argv[2:]
printed = subprocess.run([exe, *cmd, "--print-settings"], capture_output=True, text=True).stdout
helpall = subprocess.run([exe, *cmd, "--help-all"], capture_output=True, text=True).stdout
second = printed.split("# --- second tier")[1] if "# --- second tier" in printed else ""
# The option lines of --help-all: "  --a,--b TYPE=default" then the description, maybe on the next line.
spelled = {}
for m in re.finditer(r"^  (--[^\s]+)[^\n]*\n?(?:\s{20,}([^\n]*))?", helpall, re.M):
    names = m.group(1).split(",")
    also = re.search(r"\(also: ([^)]*)\)", m.group(0))
    for n in names:
        spelled[n.lstrip("-")] = (names, also.group(1).split() if also else [])
rows = []
for block in second.strip().split("\n\n"):
    lines = block.strip().splitlines()
    if len(lines) < 2 or not lines[0].startswith("# "):
        continue
    help_text = lines[0][2:]
    key, _, default = lines[1].lstrip("# ").partition("=")
    names, also = spelled.get(key, ([], []))
    flags = [n for n in names if n.lstrip("-") != key] + also
    help_text = re.sub(r" \(also: [^)]*\)", "", help_text)
    rows.append(f"| `{key}` | {default} | {', '.join('`' + f + '`' for f in flags)} | {help_text} |")
print("| setting | default | command-line spellings | what it is |")
print("|---|---|---|---|")
print("\n".join(rows))
