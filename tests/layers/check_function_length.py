#!/usr/bin/env python3
"""No function of libturb, houdini-free-io, scenes or tools over 80 lines (issue 48: a paper's stage is split into
named steps). A brace scanner, not a parser: comments and strings are blanked, and a body counts as a function's
when the text before its brace ends like a parameter list (or a constructor's initialiser list) at namespace or
class scope. Lambdas count toward the function around them.

Usage: check_function_length.py SOURCE_DIR [LIMIT]     exit 1 and one line per function over LIMIT (default 80)
"""
import os
import re
import sys

FOLDERS = ["libturb", "houdini-free-io", "scenes", "tools"]


def blank(src):
    """Comments and string/char literals replaced by spaces, line breaks kept."""
    src = re.sub(r'R"([^(\s]*)\((.*?)\)\1"', lambda m: '""' + "\n" * m.group(0).count("\n"), src, flags=re.S)
    src = re.sub(r"//[^\n]*", "", src)
    src = re.sub(r"/\*.*?\*/", lambda m: "\n" * m.group(0).count("\n"), src, flags=re.S)
    src = re.sub(r'"(\\.|[^"\\\n])*"', '""', src)
    return re.sub(r"'(\\.|[^'\\\n])*'", "''", src)


def functions(path):
    """(lines, first line, name) of every function body at namespace or class scope."""
    with open(path, encoding="utf-8", errors="replace") as f:
        s = blank(f.read())
    out, stack, line = [], [], 1
    for i, ch in enumerate(s):
        if ch == "\n":
            line += 1
        elif ch == "{":
            before = s[max(0, i - 300):i].rstrip()
            if re.search(r"(namespace[\s\w:]*|extern\s*\"\"\s*)$", before):
                kind = "scope"
            elif re.search(r"\)\s*(const)?\s*(noexcept)?\s*(override)?\s*(->\s*[\w:<>,\s]+)?$", before) or re.search(
                    r"\)\s*:\s*[^;{}]*$", before):
                kind = "function"
            elif re.search(r"(class|struct|union)\s+[\w:]*[^;{}()]*$", before):
                kind = "scope"
            else:
                kind = "block"
            stack.append((kind, line, before))
        elif ch == "}" and stack:
            kind, first, before = stack.pop()
            if kind == "function" and all(k == "scope" for k, _, _ in stack):
                names = re.findall(r"([~\w:]+)\s*\(", before)
                out.append((line - first + 1, first, names[-1] if names else "?"))
    return out


def main():
    if len(sys.argv) < 2:
        print(__doc__)
        return 2
    src, limit = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 80
    # The scanner finds what it is for: an 81-line function, and not a long class or namespace.
    probe = "namespace n {\nstruct S {\n" + "int a;\n" * 90 + "};\nint f(int x)\n{\n" + "x++;\n" * 79 + "}\n}\n"
    tmp = os.path.join(os.environ.get("TMPDIR", "/tmp"), "check_function_length_probe.cc")
    with open(tmp, "w") as f:
        f.write(probe)
    assert [n for n, _, _ in functions(tmp)] == [81], functions(tmp)
    os.remove(tmp)
    long = []
    for folder in FOLDERS:
        for dp, _, files in os.walk(os.path.join(src, folder)):
            for name in sorted(files):
                if name.endswith((".cc", ".h")):
                    path = os.path.join(dp, name)
                    long += [(n, os.path.relpath(path, src), first, fn) for n, first, fn in functions(path) if n > limit]
    for n, path, first, fn in sorted(long, reverse=True):
        print(f"{path}:{first}: {fn} is {n} lines (at most {limit}: split it into named steps)")
    print(f"{len(long)} function(s) over {limit} lines" if long else f"no function over {limit} lines")
    return 1 if long else 0


if __name__ == "__main__":
    sys.exit(main())
