#!/usr/bin/env python3
"""Import circles between the modules of a Rust crate (issue 52: no modules of a crate that
import each other, directly or in a loop).

Usage: python3 scripts/import_cycles.py crates/visnav-io/src [--edges]

Each .rs file is a module (inline modules count as their file; `#[cfg(test)] mod tests` at the
end of a file is left out). An edge A -> B is a path `crate::...`, `super::...` or `child::...`
in A (outside comments) that names module B or an item in it. Prints the edges with --edges,
then the circles (strongly connected components of more than one module); exit status 1 when
there is one. A textual approximation, not a Rust resolver: a re-export through the crate root
(`crate::Sequence`) is not followed to its module."""
import os, re, sys
src = sys.argv[1]
files = {}
for root, _, fs in os.walk(src):
    for f in fs:
        if f.endswith('.rs'):
            rel = os.path.relpath(os.path.join(root, f), src)[:-3].split(os.sep)
            if rel[-1] in ('mod', 'lib'): rel = rel[:-1]
            files[tuple(rel)] = os.path.join(root, f)
mods = set(files)
def resolve(path):
    # longest prefix that is a module
    for n in range(len(path), 0, -1):
        if tuple(path[:n]) in mods: return tuple(path[:n])
    return ()
edges = {}
for m, p in files.items():
    text = open(p).read()
    # drop test modules of the file (cfg(test) mod tests { ... } at the end) crudely
    text = re.split(r'#\[cfg\(test\)\]\s*mod tests', text)[0]
    lines = [l for l in text.split('\n') if not l.strip().startswith('//')]
    t = '\n'.join(lines)
    # a visibility path (`pub(in crate::mono)`) names no import
    t = re.sub(r'pub\(in [^)]*\)', 'pub', t)
    # child modules declared here
    children = set(re.findall(r'^\s*(?:pub(?:\([a-z]+\))?\s+)?mod\s+([a-z_0-9]+)\s*;', t, re.M))
    refs = []
    for x in re.finditer(r'\bcrate((?:::[A-Za-z_0-9]+)+)', t):
        refs.append(list(x.group(1).strip(':').split('::')))
    for x in re.finditer(r'\b((?:super::)+)(\{|[A-Za-z_0-9:]+)', t):
        up = x.group(1).count('super::')
        base = list(m[:len(m)-up]) if up <= len(m) else []
        refs.append(base + ([] if x.group(2) == '{' else x.group(2).split('::')))
    for x in re.finditer(r'\b(?:use\s+|pub use\s+|\b)(?:self::)?([a-z_0-9]+)::', t):
        if x.group(1) in children:
            refs.append(list(m) + [x.group(1)])
    # grouped crate imports use crate::{a::X, b}
    for x in re.finditer(r'use crate::\{([^}]*)\}', t):
        for part in x.group(1).split(','):
            part = part.strip()
            if part: refs.append(part.split('::'))
    for r in refs:
        tgt = resolve([s for s in r if s])
        if tgt and tgt != m and not (len(tgt) < len(m) and m[:len(tgt)] == tgt and False):
            edges.setdefault(m, set()).add(tgt)
idx, low, on, st, out, c = {}, {}, set(), [], [], [0]
sys.setrecursionlimit(10000)
def sc(v):
    idx[v] = low[v] = c[0]; c[0] += 1; st.append(v); on.add(v)
    for w in edges.get(v, ()):
        if w not in idx: sc(w); low[v] = min(low[v], low[w])
        elif w in on: low[v] = min(low[v], idx[w])
    if low[v] == idx[v]:
        comp = []
        while True:
            w = st.pop(); on.discard(w); comp.append(w)
            if w == v: break
        out.append(comp)
for v in sorted(mods):
    if v not in idx: sc(v)
if '--edges' in sys.argv:
    for a in sorted(edges):
        print('::'.join(a) or 'lib', '->', ', '.join(sorted('::'.join(b) or 'lib' for b in edges[a])))
cyc = [sorted('::'.join(x) or 'lib' for x in comp) for comp in out if len(comp) > 1]
print('import circles:', cyc if cyc else 'none')
sys.exit(1 if cyc else 0)
