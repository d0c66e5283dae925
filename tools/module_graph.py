#!/usr/bin/env python3
"""Prints the module-level dependency graph of the verisplat library and its cycles.

An edge `a -> b` means some file of module `a` (src/a.rs or src/a/...) names
`crate::b` (in a `use` line, a `use crate::{b, ...}` group, or a path in the code;
`self::` and `super::` paths are resolved to theirs). `lib` is the crate root
(src/lib.rs: the wings), above every wing: an edge to it runs up. An exported macro
lives at the crate root whatever its file, so naming it there (`crate::__console_note!`)
is a use of `lib`, except in the file that defines it, which re-exports it under its
module's path (`pub use crate::__console_note as note;` in core/console.rs, named
`crate::core::console::note!`). Comments and strings are
ignored; code under `#[cfg(test)]` counts like any other code, except with
--no-tests, which drops `#[cfg(test)] mod ... { ... }` blocks and files named
tests.rs. The binary (src/main.rs, src/cli/) uses the library as `verisplat::` and is
left out. Features (`#[cfg(feature = ...)]`) are ignored: every module counts.

    tools/module_graph.py                # the wings (core, io, ...): edges, then cycles
    tools/module_graph.py --wings        # checks that every arrow between wings runs
                                         # down core < io < fields < cpu < gpu < render
                                         # < train < app, and between render's floors
                                         # forward < frame < backward, and that none
                                         # runs up to the crate root `lib` (exit status
                                         # 1 if one runs up)
    tools/module_graph.py --depth 2      # the wings' modules as nodes (core::scene ->
                                         # core::fsutil, ...; --depth 3 their
                                         # submodules); edges between a module and its
                                         # own submodules are left out
    tools/module_graph.py --mermaid      # the edges as a mermaid flowchart
    tools/module_graph.py --layers       # the modules by layer (a cycle is one node)
    tools/module_graph.py --why a b      # the lines behind the edge a -> b
    tools/module_graph.py --src DIR      # another checkout's src/ (e.g. a git worktree)
    tools/module_graph.py --bin --depth 2
                                         # the binary instead: src/main.rs (`main`) and
                                         # src/cli/ (cli::render -> cli::common, ...)
    tools/module_graph.py --python       # the Python package instead (python/verisplat/:
                                         # torch -> _passes, ...; --layers, --mermaid,
                                         # --why too): an edge `a -> b` is an import of
                                         # module b in a's file, function-local and
                                         # `if TYPE_CHECKING:` ones included; `__init__`
                                         # is the package (`from . import Camera`)

Cycles are reported as the strongly connected components with more than one module,
each with one shortest cycle through every edge of it, so a component that is a
single loop prints exactly that loop. Exit status 1 if there is a cycle.
"""

import argparse
import os
import re
import sys
from collections import defaultdict

SRC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src")
# The binary's command-line modules (src/cli/, `mod cli;` of src/main.rs).
BIN_DIR = "cli"
# The library's wings, each using only the wings before it (checked with --wings).
WINGS = ["core", "io", "fields", "cpu", "gpu", "render", "train", "app"]
# Floors inside a wing, each using only the floors before it (checked with --wings too).
FLOORS = {"render": ["forward", "frame", "backward"]}
IDENT = r"[A-Za-z_][A-Za-z0-9_]*"


def strip_comments(text):
    """Removes // and /* */ comments and the contents of string literals."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif text.startswith("/*", i):
            depth, i = 1, i + 2
            while i < n and depth:
                if text.startswith("/*", i):
                    depth, i = depth + 1, i + 2
                elif text.startswith("*/", i):
                    depth, i = depth - 1, i + 2
                else:
                    if text[i] == "\n":
                        out.append("\n")
                    i += 1
        elif text.startswith('r#"', i) or text.startswith('r"', i):
            hashes = text[i + 1 : text.index('"', i)]
            end = '"' + hashes
            j = text.find(end, text.index('"', i) + 1)
            j = n if j < 0 else j + len(end)
            out.append('""' + "\n" * text.count("\n", i, j))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append('""' + "\n" * text.count("\n", i, j))
            i = j + 1
        elif c == "'" and re.match(r"'(\\.|[^\\'])'", text[i : i + 4]):
            # a char literal (not a lifetime)
            j = text.index("'", i + 2 if text[i + 1] == "\\" else i + 1)
            out.append("' '")
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def drop_test_modules(text):
    """Blanks `#[cfg(test)] mod name { ... }` blocks (keeping line numbers)."""
    out, pos = [], 0
    for m in re.finditer(r"#\[cfg\(test\)\]\s*(pub(\([^)]*\))?\s+)?mod\s+" + IDENT + r"\s*\{", text):
        if m.start() < pos:
            continue
        depth, j = 1, m.end()
        while j < len(text) and depth:
            depth += {"{": 1, "}": -1}.get(text[j], 0)
            j += 1
        out.append(text[pos : m.start()])
        out.append("\n" * text.count("\n", m.start(), j))
        pos = j
    out.append(text[pos:])
    return "".join(out)


def module_of(rel, depth):
    """src-relative path -> module path with at most `depth` components."""
    parts = rel[:-3].split(os.sep)
    if parts[-1] == "mod":
        parts = parts[:-1]
    if parts in (["lib"], ["main"]):
        return root_name()
    return "::".join(parts[:depth])


def group_paths(body):
    """Paths inside a `{...}` use group: 'a::b, c::{d, e}' -> ['a::b', 'c::d', 'c::e']."""
    items, depth, cur = [], 0, ""
    for ch in body:
        if ch == "," and depth == 0:
            items.append(cur)
            cur = ""
            continue
        depth += {"{": 1, "}": -1}.get(ch, 0)
        cur += ch
    items.append(cur)
    paths = []
    for item in (s.strip() for s in items):
        if not item:
            continue
        m = re.match(r"(" + IDENT + r"(?:\s*::\s*" + IDENT + r")*)\s*::\s*\{(.*)\}$", item, re.S)
        if m:
            prefix = re.sub(r"\s", "", m.group(1))
            paths += [prefix + "::" + p for p in group_paths(m.group(2))]
        else:
            paths.append(re.sub(r"\s", "", item.split(" as ")[0]))
    return paths


def inline_modules(text):
    """(start, end, name) of every inline `mod name { ... }` block."""
    out = []
    for m in re.finditer(r"\bmod\s+(" + IDENT + r")\s*\{", text):
        depth, j = 1, m.end()
        while j < len(text) and depth:
            depth += {"{": 1, "}": -1}.get(text[j], 0)
            j += 1
        out.append((m.start(), j, m.group(1)))
    return out


PREFIX = r"\b(crate|self|super(?:\s*::\s*super)*)\s*::\s*"


def references(text, module):
    """(line, absolute path) for every path in the code that starts with `crate::`,
    `self::` or `super::`, resolved against `module` (the file's module path, a list)
    and the inline modules around it."""
    inline = inline_modules(text)
    refs = []
    for m in re.finditer(PREFIX + r"(\{|" + IDENT + r"(?:\s*::\s*" + IDENT + r")*)", text):
        head = re.sub(r"\s", "", m.group(1))
        if head == "crate":
            base = []
        else:
            base = module + [name for a, b, name in inline if a < m.start() < b]
            ups = head.count("super")
            if ups > len(base):
                continue
            base = base[: len(base) - ups]
        if m.group(2) == "{":
            depth, j = 1, m.end()
            while depth:
                depth += {"{": 1, "}": -1}.get(text[j], 0)
                j += 1
            paths = group_paths(text[m.end() : j - 1])
        else:
            paths = [re.sub(r"\s", "", m.group(2))]
        line = text.count("\n", 0, m.start()) + 1
        for path in paths:
            parts = [x for x in path.split("::") if x not in ("self", "*")]
            refs.append((line, "::".join(base + parts)))
    return refs


BIN = False


def root_name():
    """The crate root's node: `lib` (src/lib.rs), or `main` (src/main.rs) with --bin."""
    return "main" if BIN else "lib"


def library_files(no_tests):
    """(src-relative path, comment-free text) of every file of the library (of the
    binary with --bin: src/main.rs and src/cli/)."""
    for dirpath, dirs, files in os.walk(SRC):
        dirs.sort()
        for f in sorted(files):
            if not f.endswith(".rs"):
                continue
            full = os.path.join(dirpath, f)
            rel = os.path.relpath(full, SRC)
            in_bin = rel == "main.rs" or rel.startswith(BIN_DIR + os.sep)
            if in_bin != BIN:
                continue
            if in_bin and rel != "main.rs":
                # the binary's modules are `cli::...` (main.rs: `mod cli;`)
                rel = os.path.relpath(full, os.path.join(SRC, os.path.dirname(BIN_DIR)))
            if no_tests and f == "tests.rs":
                continue
            with open(full, encoding="utf-8") as fh:
                text = strip_comments(fh.read())
            if no_tests:
                text = drop_test_modules(text)
            yield rel, text


def collect(depth, no_tests):
    """Modules and {(from, to): [(file, line, path)]} over the library's files.

    `lib` is the crate root (src/lib.rs and its items, exported macros included: a path
    `crate::x` to anything but a wing is an edge to it), except that the file defining an
    exported macro may name it there to re-export it.
    """
    files = list(library_files(no_tests))
    modules = {module_of(rel, d) for rel, _ in files for d in range(1, depth + 1)}
    top = {m for m in modules if "::" not in m and m != root_name()}
    macros = {}  # exported macro -> the file defining it
    for rel, text in files:
        for m in re.finditer(r"#\[macro_export\]\s*macro_rules!\s*(" + IDENT + ")", text):
            macros[m.group(1)] = rel
    edges = defaultdict(list)
    for rel, text in files:
        src = module_of(rel, depth)
        root = rel in ("lib.rs", "main.rs")
        refs = references(text, [] if root else module_of(rel, 99).split("::"))
        if root:
            # the root names its modules without `crate::`
            refs += [
                (text.count("\n", 0, m.start()) + 1, m.group(1))
                for m in re.finditer(r"(?<![:\w])(" + IDENT + r")\s*::", text)
                if m.group(1) in top
            ]
        for line, path in refs:
            parts = path.split("::")
            if parts[0] in macros and macros[parts[0]] == rel:
                dst = src  # the defining file re-exports its macro from the crate root
            elif parts[0] not in top:
                dst = root_name()
            else:
                # the target is the longest module prefix, up to `depth` parts: an item
                # like `scene::Scene` (not a submodule) falls back to `scene`
                dst = "::".join(parts[:depth])
                while dst not in modules and "::" in dst:
                    dst = dst.rsplit("::", 1)[0]
            # a submodule using its own parent (or the reverse) is no dependency between
            # modules
            if src != dst and not dst.startswith(src + "::") and not (
                dst != root_name() and src.startswith(dst + "::")
            ):
                shown = os.path.join("src", os.path.dirname(BIN_DIR), rel) if BIN and rel != "main.rs" else os.path.join("src", rel)
                edges[(src, dst)].append((shown, line, "crate::" + path))
    return sorted(modules), edges


def python_graph(package):
    """Modules and {(from, to): [(file, line, import)]} of the Python package in folder
    `package`: its modules are its files (`x.py`, and `x.pyi` for the extension), the
    package itself is `__init__`. Every import in a module's file counts, at the top,
    inside a function or under `if TYPE_CHECKING:` alike: `from . import x` (`x` a
    module, else the package), `from .x import y`, `import verisplat.x`, `from verisplat
    import x`, `from verisplat.x import y`."""
    import ast

    name = os.path.basename(os.path.normpath(package))
    files = sorted(f for f in os.listdir(package) if f.endswith((".py", ".pyi")))
    modules = sorted({f.rsplit(".", 1)[0] for f in files})
    edges = defaultdict(list)
    for f in files:
        src = f.rsplit(".", 1)[0]
        path = os.path.join(package, f)
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
        tree = ast.parse(text, f)
        for node in ast.walk(tree):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name.split(".") for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level > 1:
                    continue  # above the package
                base = (node.module or "").split(".") if node.module else []
                if node.level == 1:
                    base = [name] + base
                # `from <package> import x`: x is a module or a name of the package
                targets = [base + [a.name] if len(base) == 1 else base for a in node.names]
            for parts in targets:
                if parts[0] != name:
                    continue  # another package
                dst = parts[1] if len(parts) > 1 and parts[1] in modules else "__init__"
                if dst != src:
                    shown = os.path.relpath(path, os.path.join(SRC, ".."))
                    code = " ".join(ast.get_source_segment(text, node).split())
                    edges[(src, dst)].append((shown, node.lineno, code))
    return modules, edges


def sccs(nodes, adj):
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(adj[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in nodes:
        if v not in index:
            visit(v)
    return out


def shortest_path(adj, start, goal, within):
    prev, frontier = {start: None}, [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(adj[v]):
                if w in within and w not in prev:
                    prev[w] = v
                    if w == goal:
                        path = [w]
                        while prev[path[-1]] is not None:
                            path.append(prev[path[-1]])
                        return path[::-1]
                    nxt.append(w)
        frontier = nxt
    return None


def cycles(nodes, edges):
    adj = defaultdict(set)
    for a, b in edges:
        adj[a].add(b)
    found = []
    for comp in sccs(nodes, adj):
        if len(comp) < 2:
            continue
        members, loops = set(comp), []
        for a in comp:
            for b in sorted(adj[a] & members):
                back = shortest_path(adj, b, a, members)
                loop = [a] + back
                # canonical rotation, so the same loop found from two edges prints once
                k = loop[:-1].index(min(loop[:-1]))
                loop = loop[k:-1] + loop[:k] + [loop[k]]
                if loop not in loops:
                    loops.append(loop)
        found.append((comp, sorted(loops, key=lambda l: (len(l), l))))
    return found


def print_layers(nodes, edges):
    """Layer 0 uses no other module; layer n uses modules of layers below n only. The
    modules of a cycle share one layer, shown as {a, b}."""
    adj = defaultdict(set)
    for a, b in edges:
        adj[a].add(b)
    comps = sccs(nodes, adj)  # Tarjan gives the components dependencies first
    comp_of = {v: i for i, c in enumerate(comps) for v in c}
    level = {}
    for i, comp in enumerate(comps):
        below = {comp_of[w] for v in comp for w in adj[v]} - {i}
        level[i] = 1 + max((level[j] for j in below), default=-1)
    for n in range(max(level.values()) + 1):
        names = sorted(
            (c[0] if len(c) == 1 else "{" + ", ".join(c) + "}")
            for i, c in enumerate(comps)
            if level[i] == n
        )
        print(f"layer {n}: {', '.join(names)}")


def check_wings(nodes, edges):
    """Every edge between two wings runs down WINGS (to a wing listed earlier), and every
    edge between two floors of a wing down its FLOORS; prints the wings' edges and each
    edge that runs up, with the lines behind it. The crate root (`lib`: the wings) is above
    every wing: an edge from a wing to it runs up."""
    wing = {w: i for i, w in enumerate(WINGS)}
    extra = sorted(n for n in nodes if "::" not in n and n != root_name() and n not in wing)
    bad = []
    down = defaultdict(set)
    for (a, b), sites in sorted(edges.items()):
        wa, wb = a.split("::")[0], b.split("::")[0]
        if wb == root_name() and wa != wb:
            bad.append((a, b, sites[0]))
        if root_name() in (wa, wb) or wa == wb:
            continue
        down[wa].add(wb)
        if wa in wing and wb in wing and wing[wb] >= wing[wa]:
            bad.append((a, b, sites[0]))
    for w in WINGS:
        print(f"{w:<7} -> {', '.join(sorted(down[w], key=wing.get)) or '(nothing)'}")
    print()
    if extra:
        print(f"modules outside the wings: {', '.join(extra)}")
    for wing_name, floors in FLOORS.items():
        level = {f"{wing_name}::{f}": i for i, f in enumerate(floors)}
        floor_of = lambda m: next((x for x in level if m == x or m.startswith(x + "::")), None)
        for (a, b), sites in sorted(edges.items()):
            fa, fb = floor_of(a), floor_of(b)
            if fa and fb and fa != fb and level[fb] > level[fa]:
                bad.append((a, b, sites[0]))
        print(f"{wing_name} floors: {' < '.join(floors)}")
    for a, b, (f, line, path) in bad:
        print(f"arrow up: {a} -> {b} ({f}:{line}: {path})")
    if not extra and not bad:
        print("wings: every arrow runs down " + " < ".join(WINGS))
        return 0
    return 1


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--depth", type=int, default=1)
    ap.add_argument("--no-tests", action="store_true")
    ap.add_argument("--mermaid", action="store_true")
    ap.add_argument("--layers", action="store_true")
    ap.add_argument("--why", nargs=2, metavar=("FROM", "TO"))
    ap.add_argument("--src", help="the crate's src folder (default: this checkout's)")
    ap.add_argument("--bin", action="store_true", help="the binary (main.rs, cli/), not the library")
    ap.add_argument("--wings", action="store_true", help="check that every arrow between wings runs down")
    ap.add_argument("--python", action="store_true", help="the Python package (python/verisplat/), not the crate")
    args = ap.parse_args()
    if args.bin:
        global BIN
        BIN = True
    if args.src:
        global SRC
        SRC = args.src
    if args.python:
        nodes, edges = python_graph(os.path.join(SRC, "..", "python", "verisplat"))
    else:
        nodes, edges = collect(args.depth, args.no_tests)

    if args.wings and not args.python:
        # the wings' edges are the edges of every module, cut to their first part
        return check_wings(nodes, collect(99, args.no_tests)[1]) | (1 if cycles(nodes, edges) else 0)
    if args.why:
        for f, line, path in edges.get(tuple(args.why), []):
            print(f"{f}:{line}: {path}")
        return 0
    if args.layers:
        print_layers(nodes, edges)
    elif args.mermaid:
        print("flowchart TD")
        for a, b in sorted(edges):
            print(f"    {a.replace('::', '_')} --> {b.replace('::', '_')}")
    else:
        shown = nodes if args.depth == 1 or args.python else [a for a, _ in edges]
        width = max((len(a) for a in shown), default=0)
        for a in nodes:
            outs = sorted(b for x, b in edges if x == a)
            if outs or args.depth == 1 or args.python:
                print(f"{a:<{width}} -> {', '.join(outs) if outs else '(nothing)'}")
    found = cycles(nodes, edges)
    print()
    if not found:
        print("cycles: none")
        return 0
    print("cycles:")
    for comp, loops in found:
        print(f"  component {{{', '.join(comp)}}}:")
        for loop in loops:
            hops = []
            for a, b in zip(loop, loop[1:]):
                f, line, _ = edges[(a, b)][0]
                hops.append(f"{a} -> {b} ({f}:{line})")
            print("    " + " -> ".join(loop))
            for h in hops:
                print("        " + h)
    return 1


if __name__ == "__main__":
    sys.exit(main())
