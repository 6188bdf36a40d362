#!/usr/bin/env python3
"""Finds import loops between the top-level modules of each crate of the workspace.

For every crate root (`src/lib.rs`, `src/main.rs`, `src/bin/*.rs`) the module tree is
walked from its `mod` declarations; a path `crate::m::…` (or a `super::…` that climbs to
the crate root and names `m`) in a file of top-level module `t` is an edge t → m. Loops
are the strongly connected components with more than one module. Edges from test-only
code (`#[cfg(test)]` modules) are reported apart: they may reach up a layer to test how
modules work together.

    python3 scripts/check_module_loops.py          # exit status 1 when a loop exists
"""

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MOD_DECL = re.compile(r"(#\[cfg\(test\)\]\s*)?(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*([;{])")
PATH = re.compile(r"\b((?:super::)+|crate::)(\w+)")


def strip_comments_and_strings(text):
    """The text with comments and string literals blanked (lengths kept)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == '"' or (c == "r" and re.match(r'r#*"', text[i:])):
            m = re.match(r'r(#*)"', text[i:])
            if m:
                end = '"' + m.group(1)
                j = text.find(end, i + len(m.group(0)))
                j = n if j < 0 else j + len(end)
            else:
                j = i + 1
                while j < n and text[j] != '"':
                    j += 2 if text[j] == "\\" else 1
                j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "'" and re.match(r"'(\\.|[^\\'])'", text[i:]):
            m = re.match(r"'(\\.|[^\\'])'", text[i:])
            out.append(" " * len(m.group(0)))
            i += len(m.group(0))
        else:
            out.append(c)
            i += 1
    return "".join(out)


def block_end(code, open_at):
    depth = 0
    for j in range(open_at, len(code)):
        if code[j] == "{":
            depth += 1
        elif code[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    return len(code)


def child_file(parent_file, parent_is_dir_owner, name):
    base = parent_file.parent if parent_is_dir_owner else parent_file.with_suffix("")
    for candidate in (base / f"{name}.rs", base / name / "mod.rs"):
        if candidate.exists():
            return candidate
    return None


def walk(file, modpath, is_dir_owner, test_only, edges, modules):
    """Records the edges of `file` (module `modpath`) and of its inline and file modules."""
    code = strip_comments_and_strings(file.read_text())
    spans = [(0, len(code), modpath, test_only)]
    for m in MOD_DECL.finditer(code):
        child_test = test_only or bool(m.group(1))
        child = modpath + [m.group(2)]
        if not modpath:
            modules.add(m.group(2))
        if m.group(3) == "{":
            open_at = m.end() - 1
            spans.append((open_at, block_end(code, open_at), child, child_test))
        else:
            path = child_file(file, is_dir_owner, m.group(2))
            if path is not None:
                walk(path, child, path.name == "mod.rs", child_test, edges, modules)
    for m in PATH.finditer(code):
        # The innermost span holding the path gives its module.
        at = m.start()
        start, end, here, test = max(
            (s for s in spans if s[0] <= at < s[1]), key=lambda s: s[0]
        )
        if m.group(1) == "crate::":
            target = m.group(2)
        else:
            ups = m.group(1).count("super")
            if ups < len(here):
                target = (here[: len(here) - ups] + [m.group(2)])[0]
            elif ups == len(here):
                target = m.group(2)
            else:
                continue
        if here and target != here[0]:
            edges.add((here[0], target, test))


def loops(nodes, edges):
    """Strongly connected components with more than one node (Tarjan)."""
    graph = {v: sorted({b for a, b in edges if a == v}) for v in nodes}
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, []):
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


def main():
    found = False
    for manifest in sorted(ROOT.glob("**/Cargo.toml")):
        if "target" in manifest.parts or manifest.parent == ROOT:
            continue
        src = manifest.parent / "src"
        roots = [p for p in (src / "lib.rs", src / "main.rs") if p.exists()]
        roots += sorted((src / "bin").glob("*.rs")) if (src / "bin").is_dir() else []
        for root in roots:
            edges, modules = set(), set()
            walk(root, [], True, False, edges, modules)
            edges = {(a, b, t) for a, b, t in edges if b in modules}
            name = root.relative_to(ROOT)
            always = {(a, b) for a, b, t in edges if not t}
            every = {(a, b) for a, b, _ in edges}
            plain, with_tests = loops(modules, always), loops(modules, every)
            for comp in plain:
                found = True
                print(f"{name}: loop among {', '.join(comp)}")
            for comp in with_tests:
                if comp not in plain:
                    test_edges = sorted(
                        f"{a} -> {b}" for a, b, t in edges if t and a in comp and b in comp
                    )
                    print(f"{name}: loop through test code only among {', '.join(comp)} "
                          f"(test edges: {'; '.join(test_edges)})")
            if not plain and not with_tests:
                print(f"{name}: no loops ({len(modules)} modules, {len(always)} edges)")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
