#!/usr/bin/env python3
"""File-level import cycles inside each crate: which source files name another module of the
same crate (`crate::a::b`, `super::x` in code, not in comments), and every cycle among them
(strongly connected components of two or more files; a parent and its own children excepted).
Test modules (`#[cfg(test)] mod tests`) are left out.

Usage: python3 scripts/module_cycles.py   (prints the cycles; exit 1 when there is one)
"""
import os
import re
import sys


def modules(src):
    """Module path (tuple) -> file, for a crate's src folder."""
    out = {}
    for root, _, files in os.walk(src):
        for f in files:
            if not f.endswith(".rs"):
                continue
            rel = os.path.relpath(os.path.join(root, f), src)[:-3].split(os.sep)
            if rel[-1] in ("lib", "main"):
                rel = rel[:-1]
            elif rel[-1] == "mod":
                rel = rel[:-1]
            out[tuple(rel)] = os.path.join(root, f)
    return out


def refs(path, me, mods):
    text = open(path).read()
    cut = text.find("#[cfg(test)]")
    if cut >= 0:
        text = text[:cut]
    # Comments (doc links included) name modules without importing them.
    text = "\n".join(l for l in text.splitlines() if not l.lstrip().startswith("//"))
    found = set()
    for m in re.finditer(r"\bcrate::((?:[a-z_][a-z0-9_]*::)*[a-z_][a-z0-9_]*)", text):
        parts = tuple(m.group(1).split("::"))
        for k in range(len(parts), 0, -1):
            if parts[:k] in mods:
                found.add(parts[:k])
                break
    for m in re.finditer(r"\bsuper::((?:[a-z_][a-z0-9_]*::)*[a-z_][a-z0-9_]*)", text):
        base = me[:-1] if os.path.basename(path) != "mod.rs" else me[:-1]
        parts = base + tuple(m.group(1).split("::"))
        for k in range(len(parts), len(base), -1):
            if parts[:k] in mods:
                found.add(parts[:k])
                break
        else:
            if base in mods:
                found.add(base)
    found.discard(me)
    # A module naming its own descendants, or a child its ancestors' items, is not a cycle of
    # siblings; keep only references between modules neither of which contains the other.
    return {r for r in found if r[: len(me)] != me and me[: len(r)] != r}


def main():
    bad = 0
    for crate in sorted(os.listdir("crates")):
        src = os.path.join("crates", crate, "src")
        if not os.path.isdir(src):
            continue
        mods = modules(src)
        graph = {m: refs(p, m, mods) for m, p in mods.items()}
        # Strongly connected components (Tarjan): any with two or more files is a cycle.
        index, low, stack, on, comps = {}, {}, [], set(), []

        def visit(v):
            index[v] = low[v] = len(index)
            stack.append(v)
            on.add(v)
            for w in graph[v]:
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
                comps.append(comp)

        for v in graph:
            if v not in index:
                visit(v)
        for comp in comps:
            if len(comp) > 1:
                print(f"{crate}: cycle among " + ", ".join("::".join(m) for m in sorted(comp)))
                bad += 1
    print(f"{bad} cycles")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
