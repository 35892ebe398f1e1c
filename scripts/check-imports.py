#!/usr/bin/env python3
"""Fails when two source files of a crate import each other (outside tests).

A file imports another when its code names a path into it: `use crate::a::b`, `crate::a::f()`,
`super::x`, `self::y` in a module with children. Paths are resolved to files through `mod`
declarations and through the crate root's `pub use` re-exports (so `crate::Error`, re-exported
from `error.rs`, is an edge to `error.rs`). The crate root (`lib.rs`, `main.rs`) is the
hierarchy that declares and re-exports the modules, so edges out of it are not counted.
`#[cfg(test)]` modules and comments are ignored.

Usage: scripts/check-imports.py [WORKSPACE_ROOT]   (standard library only; no venv)
"""

import pathlib
import re
import sys

root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).parent.parent)


def strip_comments_and_strings(text):
    """One pass over the source: drops comments, empties string and char literals."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        starts_word = i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")
        raw = re.match(r'b?r(#*)"', text[i : i + 260]) if c in "br" and starts_word else None
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
        elif raw:
            end = text.find('"' + raw.group(1), i + raw.end())
            out.append('""')
            i = n if end < 0 else end + 1 + len(raw.group(1))
        elif c == '"':
            i += 1
            while i < n and text[i] != '"':
                i += 2 if text[i] == "\\" else 1
            out.append('""')
            i += 1
        elif c == "'" and (m := re.match(r"'(\\.[^']*|[^'\\])'", text[i : i + 12])):
            out.append("' '")
            i += m.end()
        else:
            out.append(c)
            i += 1
    return "".join(out)


def code_of(path):
    """The file's text without comments, string contents and #[cfg(test)] items."""
    text = strip_comments_and_strings(path.read_text())
    out, i = [], 0
    for m in re.finditer(r"#\[cfg\(test\)\]", text):
        if m.start() < i:
            continue
        out.append(text[i : m.start()])
        # Skip the attributed item: up to the end of its brace block or its semicolon.
        j, depth = m.end(), 0
        while j < len(text):
            c = text[j]
            if c == "{":
                depth += 1
            elif c == "}":
                depth -= 1
                if depth == 0:
                    j += 1
                    break
            elif c == ";" and depth == 0:
                j += 1
                break
            j += 1
        i = j
    out.append(text[i:])
    return "".join(out)


def module_files(src):
    """Maps module paths (tuples) to files, following `mod x;` from each crate root."""
    mods = {}

    def visit(path, modpath):
        mods[modpath] = path
        code = code_of(path)
        is_dir_owner = path.name in ("lib.rs", "main.rs", "mod.rs")
        base = path.parent if is_dir_owner else path.parent / path.stem
        for m in re.finditer(r"(?m)^\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;", code):
            name = m.group(1)
            for cand in (base / f"{name}.rs", base / name / "mod.rs"):
                if cand.is_file():
                    visit(cand, modpath + (name,))
                    break

    for crate_root in ("lib.rs", "main.rs"):
        if (src / crate_root).is_file():
            visit(src / crate_root, ())
    return mods


def expand_use(tree):
    """`a::{b, c::{d, e}}` -> ['a::b', 'a::c::d', 'a::c::e'] (aliases dropped)."""
    tree = re.sub(r"\s+", "", tree)
    m = re.match(r"^(.*?)\{(.*)\}$", tree)
    if not m:
        return [tree.split("as")[0] if "::" in tree else tree]
    prefix, body = m.groups()
    parts, depth, cur = [], 0, ""
    for c in body:
        if c == "," and depth == 0:
            parts.append(cur)
            cur = ""
            continue
        depth += c == "{"
        depth -= c == "}"
        cur += c
    parts.append(cur)
    return [p for part in parts if part for p in expand_use(prefix + part)]


def referenced_paths(code):
    paths = []
    for m in re.finditer(r"\buse\s+([^;]+);", code):
        paths.extend(expand_use(m.group(1)))
    for m in re.finditer(r"\b((?:crate|super|self)(?:::\w+)+)", code):
        paths.append(m.group(1))
    return paths


def check_crate(src):
    mods = module_files(src)
    root_code = code_of(src / "lib.rs") if (src / "lib.rs").is_file() else ""
    reexports = {}
    for path in (p for m in re.finditer(r"\bpub\s+use\s+([^;]+);", root_code) for p in expand_use(m.group(1))):
        segs = [s for s in path.split("::") if s not in ("crate", "self")]
        if len(segs) >= 2 and (segs[0],) in mods:
            reexports[segs[-1]] = (segs[0],)
    edges = {}
    for modpath, file in mods.items():
        if modpath == ():
            continue
        targets = set()
        for path in referenced_paths(code_of(file)):
            segs = path.split("::")
            if segs[0] == "crate":
                base, rest = (), segs[1:]
            elif segs[0] == "super":
                base, rest = modpath[:-1], segs[1:]
                while rest and rest[0] == "super":
                    base, rest = base[:-1], rest[1:]
            elif segs[0] == "self":
                base, rest = modpath, segs[1:]
            else:
                continue
            target = base
            for s in rest:
                if target + (s,) in mods:
                    target = target + (s,)
                else:
                    break
            if target == () and rest and rest[0] in reexports:
                target = reexports[rest[0]]
            if target not in (modpath, ()):
                targets.add(target)
        edges[modpath] = targets
    cycles = []
    for a, ts in edges.items():
        for b in ts:
            if a in edges.get(b, ()) and a < b:
                cycles.append((mods[a], mods[b]))
    return cycles


bad = []
for manifest in sorted(root.glob("*/Cargo.toml")):
    src = manifest.parent / "src"
    if src.is_dir():
        bad.extend(check_crate(src))
for a, b in bad:
    print(f"import cycle: {a.relative_to(root)} <-> {b.relative_to(root)}")
if bad:
    sys.exit(1)
print("imports: no two source files import each other")
