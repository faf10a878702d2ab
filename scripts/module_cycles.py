#!/usr/bin/env python3
"""Import cycles between modules of each crate: a module (a file) that reaches itself through
`use crate::...` / `use super::...` edges to modules that are not its ancestors or descendants
(a parent re-exporting its children is not a cycle). Prints each cycle's modules; exit 1 if any.

    python3 scripts/module_cycles.py [crate_src_dir ...]
"""
import os
import re
import sys

USE = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?use\s+([^;]+);", re.M)


def modules(src):
    mods = {}
    for root, _, files in os.walk(src):
        for f in files:
            if not f.endswith(".rs"):
                continue
            p = os.path.join(root, f)
            rel = os.path.relpath(p, src)[:-3].split(os.sep)
            if rel[-1] in ("mod", "lib", "main"):
                rel = rel[:-1]
            mods[tuple(rel)] = p
    return mods


def strip_tests(text):
    i = text.find("#[cfg(test)]")
    return text if i < 0 else text[:i]


def paths(tree, prefix=()):
    """The module paths named by a use tree (`a::{b, c::d}` -> a::b, a::c::d)."""
    tree = tree.strip()
    m = re.match(r"^([\w:]*?)(::)?\{(.*)\}$", tree, re.S)
    if m:
        base = tuple(x for x in m.group(1).split("::") if x)
        depth, cur, parts = 0, "", []
        for ch in m.group(3):
            if ch == "{":
                depth += 1
            elif ch == "}":
                depth -= 1
            if ch == "," and depth == 0:
                parts.append(cur)
                cur = ""
            else:
                cur += ch
        parts.append(cur)
        out = []
        for part in parts:
            if part.strip():
                out += paths(part, prefix + base)
        return out
    tree = tree.split(" as ")[0]
    return [prefix + tuple(x for x in tree.split("::") if x)]


def resolve(mod, path, mods):
    if not path:
        return None
    if path[0] == "crate":
        full = path[1:]
    elif path[0] in ("super", "self"):
        base = list(mod)
        i = 0
        while i < len(path) and path[i] in ("super", "self"):
            if path[i] == "super":
                base = base[:-1]
            i += 1
        full = tuple(base) + path[i:]
    else:
        return None
    while full and full not in mods:
        full = full[:-1]
    return full if full in mods else None


def related(a, b):
    return a[: len(b)] == b or b[: len(a)] == a


def cycles(src):
    mods = modules(src)
    edges = {m: set() for m in mods}
    for m, p in mods.items():
        with open(p, encoding="utf-8") as fh:
            text = strip_tests(fh.read())
        for tree in USE.findall(text):
            for path in paths(tree):
                t = resolve(m, path, mods)
                if t is not None and t != m and not related(m, t):
                    edges[m].add(t)
    # Tarjan's strongly connected components.
    index, low, stack, on, out = {}, {}, [], set(), []
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges[v]:
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
                out.append(comp)

    for v in mods:
        if v not in index:
            visit(v)
    return out


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    srcs = sys.argv[1:] or sorted(
        os.path.join(root, d, "src")
        for d in os.listdir(root)
        if os.path.isdir(os.path.join(root, d, "src")) and d != "target"
    ) + [os.path.join(root, "src")]
    found = 0
    for src in dict.fromkeys(srcs):
        for comp in cycles(src):
            found += 1
            names = sorted("::".join(c) or "<crate root>" for c in comp)
            print(f"{os.path.relpath(src, root)}: " + " <-> ".join(names))
    print(f"{found} import cycle(s)")
    sys.exit(1 if found else 0)


if __name__ == "__main__":
    main()
