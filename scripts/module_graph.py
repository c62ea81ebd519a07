#!/usr/bin/env python3
"""The import graph between a Rust crate's modules, and its cycles.

An import is a `crate::` path (or a `super::` path that leaves the module) in code outside
tests: comments (doc links included) and `#[cfg(test)]` items are skipped. Prints, for each
top-level module, the top-level modules it imports, then the cycles among them; with
`--nested`, the same for the submodules of each directory module (siblings importing each
other). Exits 1 when there is a cycle.

    scripts/module_graph.py bake/src [--nested]
"""

import re
import sys
from pathlib import Path

IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
CHAR = re.compile(r"'(\\.[^']*|[^\\'])'")


def strip_comments_and_strings(text):
    """`text` with comments removed and string and char literals emptied."""
    out, i, n = [], 0, len(text)
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
                    i += 1
        elif (m := re.compile(r'b?r(#*)"').match(text, i)) and (
            i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")
        ):
            end = text.find('"' + m.group(1), m.end())
            out.append('""')
            i = n if end < 0 else end + 1 + len(m.group(1))
        elif c == '"':
            i += 1
            while i < n and text[i] != '"':
                i += 2 if text[i] == "\\" else 1
            out.append('""')
            i += 1
        elif c == "'" and (m := CHAR.match(text, i)):
            out.append("' '")
            i = m.end()
        else:
            out.append(c)
            i += 1
    return "".join(out)


def item_end(code, i):
    """The end of the item starting at `i`: after its `;` or its matching `}`."""
    depth = 0
    while i < len(code):
        c = code[i]
        if c in "([":
            depth += 1
        elif c in ")]":
            depth -= 1
        elif c == ";" and depth == 0:
            return i + 1
        elif c == "{" and depth == 0:
            braces, i = 1, i + 1
            while i < len(code) and braces:
                braces += {"{": 1, "}": -1}.get(code[i], 0)
                i += 1
            return i
        i += 1
    return i


def strip_tests(code):
    """`code` without `#[cfg(test)]` items; also the names of `mod x;` declared under it."""
    test_mods, out, i = [], [], 0
    for m in re.finditer(r"#\[cfg\(test\)\]", code):
        if m.start() < i:
            continue
        out.append(code[i : m.start()])
        end = item_end(code, m.end())
        decl = re.match(r"\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;", code[m.end() : end])
        if decl:
            test_mods.append(decl.group(1))
        i = end
    out.append(code[i:])
    return "".join(out), test_mods


def use_tree_heads(code, start):
    """The first path segment of each branch of the `{...}` group opening at `start`."""
    depth, j, heads, expect = 0, start, [], True
    while j < len(code):
        c = code[j]
        if c == "{":
            depth += 1
            expect = depth == 1
        elif c == "}":
            depth -= 1
            if depth == 0:
                break
        elif c == "," and depth == 1:
            expect = True
        elif expect and depth == 1 and (m := IDENT.match(code, j)):
            heads.append(m.group(0))
            expect = False
            j = m.end()
            continue
        j += 1
    return heads


def module_path(src, path):
    """The module path of file `path` under `src`: `lib.rs` is `[]`, `a/b.rs` `[a, b]`."""
    parts = list(path.relative_to(src).with_suffix("").parts)
    if parts[-1] in ("mod", "lib", "main"):
        parts.pop()
    return parts


def imports(code, own):
    """Absolute module paths (lists of segments) that `code` of module `own` names."""
    found = []
    for m in re.finditer(r"\b(crate|super(?:\s*::\s*super)*)\s*::\s*", code):
        if m.group(1) == "crate":
            base = []
        else:
            ups = m.group(1).count("super")
            # A file's own module is `own`; `super` is its parent.
            base = own[: max(len(own) - ups, 0)]
        rest = code[m.end() :]
        if rest.startswith("{"):
            for head in use_tree_heads(code, m.end()):
                found.append(base + [head])
        else:
            segs = re.match(r"\w+(?:\s*::\s*\w+)*", rest)
            if segs:
                found.append(base + [s.strip() for s in segs.group(0).split("::")])
    return found


def scan(src):
    """Per module path (tuple), the set of module paths it imports, test files left out."""
    files = sorted(src.rglob("*.rs"))
    modules = {tuple(module_path(src, f)) for f in files}
    test_files, graph = set(), {}
    for f in files:
        own = module_path(src, f)
        code, test_mods = strip_tests(strip_comments_and_strings(f.read_text()))
        folder = f.parent if f.name in ("mod.rs", "lib.rs", "main.rs") else f.with_suffix("")
        for t in test_mods:
            test_files |= {folder / f"{t}.rs", folder / t / "mod.rs"}
            test_files |= set((folder / t).rglob("*.rs"))
        graph[tuple(own)] = (f, code)
    edges = {}
    for own, (f, code) in graph.items():
        if f in test_files:
            continue
        targets = set()
        for path in imports(code, list(own)):
            # The longest prefix that is a module: `crate::a::b::Item` imports module a::b.
            while path and tuple(path) not in modules:
                path = path[:-1]
            targets.add(tuple(path))
        edges[own] = targets
    return edges


def cycles(nodes, edges):
    """Strongly connected components of more than one node (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
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
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return out


def report(title, parent, edges):
    """Prints the graph among the children of `parent`; returns its cycles."""
    depth = len(parent) + 1
    nodes, graph = set(), {}
    for own, targets in edges.items():
        if len(own) < depth or own[: depth - 1] != parent:
            continue
        node = own[:depth]
        nodes.add(node)
        for t in targets:
            if len(t) >= depth and t[: depth - 1] == parent and t[:depth] != node:
                graph.setdefault(node, set()).add(t[:depth])
    if len(nodes) < 2:
        return []
    name = lambda n: "::".join(n)
    print(title)
    for n in sorted(nodes):
        print(f"  {name(n)} -> {', '.join(sorted(name(t) for t in graph.get(n, ()))) or '-'}")
    found = cycles(nodes, graph)
    for c in found:
        print(f"  CYCLE: {' <-> '.join(name(n) for n in c)}")
    return found


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    src = Path(args[0] if args else "src")
    edges = scan(src)
    found = report(f"{src}: top-level modules", (), edges)
    if "--nested" in sys.argv:
        for parent in sorted({own[:1] for own in edges if len(own) > 1}):
            found += report(f"{src}: inside {'::'.join(parent)}", parent, edges)
    print(f"{len(found)} cycle(s)")
    sys.exit(1 if found else 0)


if __name__ == "__main__":
    main()
