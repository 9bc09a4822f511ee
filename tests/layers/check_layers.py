#!/usr/bin/env python3
"""What may include what (docs/architecture.md, "What may import what"), checked on the source tree.

Fails (exit 1, one line per violation) when
  - a libturb folder includes a header of a folder it may not use (a higher layer, or another system),
  - libturb includes the IO layer, the scenes or tools,
  - the IO layer or the scenes include a system's header beyond the exceptions listed here,
  - tools/ includes a library-private header (anything under libturb/src, houdini-free-io/src, scenes/src),
  - libturb's headers include each other in a circle, or the files of tools/ depend on each other in a circle
    (a unit is a .h and its .cc: main.cc using Console.h while Console.cc uses what main.cc defines is one).

Usage: check_layers.py SOURCE_DIR [--self-test]
"""
import os
import re
import sys

# The folders of libturb/src and the folders each may include (besides its own); the entry points (run) also read and
# write files through the IO layer and run the built-in scenes. The order is the layering:
# core (fields, operators, advection, projection, parallel) < pictures and measures < the paper systems < the
# entry points. A system does not include another system.
ALLOWED = {
    "core": set(),
    "render": {"core"},
    "measure": {"core", "farm"},  # measure reads the farm's tile borders to measure at the joins
    "transfer": {"core", "measure"},  # the vorticity cap is measure's vort_peak (docs/look.md)
    "synth": {"core", "render"},  # exemplars are images
    "stylize": {"core", "render"},
    "animate": {"core", "render"},
    "farm": {"core"},
    "run": {"core", "render", "measure", "transfer", "synth", "stylize", "animate", "farm"},
}
# Libraries beside libturb: the folders of libturb each may include, and single headers allowed beyond them.
OUTSIDE = {
    # stroke files are read into animate's FlowStroke and CloneStroke
    "houdini-free-io": ({"core", "render"}, {"FlowDesign.h", "CloneBrush.h"}),
    "scenes": ({"core", "render", "measure"}, set()),
}
# tools/, bottom up: a file includes headers of its own level or lower, so no two files use each other across levels.
# Commands.h declares the shared option builders (Options.cc) and the command table (main.cc).
TOOLS_LEVELS = [
    {"Validators", "CommandLine"},
    {"Console"},
    {"Commands", "Options", "Preflight", "RunReport", "StylizeCommon"},
    {"cmd_*"},
    {"main", "cli_main", "vdbturb_module"},
]


def tools_level(name):
    for level, names in enumerate(TOOLS_LEVELS):
        if name in names or (name.startswith("cmd_") and "cmd_*" in names):
            return level
    return None


INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^>"]+)[>"]', re.M)


def includes(path):
    with open(path, encoding="utf-8", errors="replace") as f:
        return INCLUDE.findall(f.read())


def sources(root, exts=(".cc", ".h")):
    for dp, _, files in os.walk(root):
        for name in sorted(files):
            if name.endswith(exts):
                yield os.path.join(dp, name)


def header_folders(src):
    """Public header name -> the libturb/src folder its implementation lives in (core for data-only headers)."""
    impl = {}
    for path in sources(os.path.join(src, "libturb", "src")):
        folder = os.path.relpath(path, os.path.join(src, "libturb", "src")).split(os.sep)[0]
        if folder == "run":  # the entry points' headers are include/turb/run/'s: a flat header is never theirs
            continue
        impl.setdefault(os.path.splitext(os.path.basename(path))[0], folder)
    out = {}
    pub = os.path.join(src, "libturb", "include", "turb")
    for path in sources(pub, (".h",)):
        rel = os.path.relpath(path, pub).replace(os.sep, "/")
        # include/turb/run/X.h is the run folder's; a flat header belongs where its implementation lives.
        out[rel] = rel.split("/")[0] if "/" in rel else impl.get(rel[:-2], "core")
    return out


def find_cycle(graph):
    """A circle in `graph` (unit -> set of units) as a list of units, or None."""
    state = {}

    def visit(u, path):
        state[u] = 1
        path.append(u)
        for v in sorted(graph.get(u, ())):
            if state.get(v) == 1:
                return path[path.index(v):] + [v]
            if v not in state:
                c = visit(v, path)
                if c:
                    return c
        path.pop()
        state[u] = 2
        return None

    for u in sorted(graph):
        if u not in state:
            c = visit(u, [])
            if c:
                return c
    return None


def unit(path):
    return os.path.splitext(os.path.basename(path))[0]


def check(src):
    errors = []
    folders = header_folders(src)
    lib_src = os.path.join(src, "libturb", "src")
    # libturb: folder rules and circles within a folder.
    graphs = {}
    for path in sources(lib_src):
        rel = os.path.relpath(path, src)
        folder = os.path.relpath(path, lib_src).split(os.sep)[0]
        if folder not in ALLOWED:
            errors.append(f"{rel}: libturb/src/{folder} is not a known folder (add it to the layers)")
            continue
        g = graphs.setdefault(folder, {})
        for kind, inc in includes(path):
            if (inc.startswith(("turbio/", "scenes/")) and folder != "run") or (kind == '"' and "tools/" in inc):
                errors.append(f"{rel}: libturb includes {inc} (the IO layer, scenes and tools sit above it)")
            elif inc.startswith("turb/"):
                name = inc[len("turb/"):]
                to = folders.get(name)
                if to and to != folder and to not in ALLOWED[folder]:
                    errors.append(f"{rel}: {folder} includes <{inc}> of {to}, which it may not use")
                if path.endswith(".h") and to == folder:
                    g.setdefault(os.path.basename(path), set()).add(name)
            elif kind == '"':
                target = os.path.normpath(os.path.join(os.path.dirname(path), inc))
                to = os.path.relpath(target, lib_src).split(os.sep)[0]
                if to != folder and to not in ALLOWED[folder]:
                    errors.append(f'{rel}: {folder} includes "{inc}" of {to}, which it may not use')
                if path.endswith(".h") and to == folder:
                    g.setdefault(os.path.basename(path), set()).add(os.path.basename(target))
    # Headers in include/turb form circles too: a public header including another of its folder.
    pub = os.path.join(src, "libturb", "include", "turb")
    for path in sources(pub):
        key = os.path.relpath(path, pub).replace(os.sep, "/")
        folder = folders.get(key, "core")
        for _, inc in includes(path):
            if inc.startswith("turb/"):
                to = folders.get(inc[len("turb/"):])
                if to and to != folder and to not in ALLOWED.get(folder, set()):
                    errors.append(f"{os.path.relpath(path, src)}: {folder}'s header includes <{inc}> of {to}")
                if to == folder:
                    graphs.setdefault(folder, {}).setdefault(key, set()).add(inc[len("turb/"):])
            elif inc.startswith(("turbio/", "scenes/")) and folder != "run":
                errors.append(f"{os.path.relpath(path, src)}: a libturb header includes {inc}")
    for folder, g in sorted(graphs.items()):
        c = find_cycle(g)
        if c:
            errors.append(f"libturb/src/{folder}: include circle " + " -> ".join(c))
    # The IO layer and the scenes.
    for lib, (may, extra) in OUTSIDE.items():
        for path in sources(os.path.join(src, lib)):
            for kind, inc in includes(path):
                if inc.startswith("turb/"):
                    name = inc[len("turb/"):]
                    to = folders.get(name, "core")
                    if to not in may and name not in extra:
                        errors.append(f"{os.path.relpath(path, src)}: {lib} includes <{inc}> of {to}")
                elif kind == '"' and "tools/" in inc:
                    errors.append(f"{os.path.relpath(path, src)}: {lib} includes {inc} from tools/")
    # tools/: public headers only, and each file includes only its own level or the levels below (TOOLS_LEVELS).
    tools = os.path.join(src, "tools")
    private = {unit(p) for lib in ("libturb/src", "houdini-free-io/src", "scenes/src")
               for p in sources(os.path.join(src, lib), (".h",))}
    own = {unit(p) for p in sources(tools, (".h",))}
    for path in sources(tools):
        rel = os.path.relpath(path, src)
        level = tools_level(unit(path))
        if level is None:
            errors.append(f"{rel}: not in the tools/ levels of tests/layers/check_layers.py (add it)")
            continue
        for kind, inc in includes(path):
            if "src/" in inc or (kind == '"' and unit(inc) in private and unit(inc) not in own):
                errors.append(f'{rel}: tools/ includes the library-private header "{inc}"')
            elif kind == '"' and unit(inc) in own:
                to = tools_level(unit(inc))
                if to is not None and to > level:
                    errors.append(f'{rel}: includes "{inc}", a higher level of tools/ (a circle: what it uses '
                                  "uses it)")
    return errors


def self_test():
    """The checker finds what it is for: a circle, and no false one."""
    assert find_cycle({"a": {"b"}, "b": {"a"}}) == ["a", "b", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert find_cycle({"main": {"Console"}, "Console": {"Validators"}, "Options": {"Console", "Validators"}}) is None


def main():
    if len(sys.argv) < 2:
        print(__doc__)
        return 2
    self_test()
    errors = check(sys.argv[1])
    for e in errors:
        print(e)
    print(f"{len(errors)} include(s) break the layers" if errors else "the includes follow the layers")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
