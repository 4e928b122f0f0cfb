#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""The core's files call each other in layers, never in a circle.

Reads the symbols of the core's static library (nm), links each object file to the files whose
functions or data it uses, and fails on any strongly connected set of two or more files (a circle such
as params.c -> numerics.c -> units.c -> params.c). Usage: check_core_cycles.py NM LIBVAFM_INTERNAL.a
"""
import subprocess
import sys


def graph(nm, archive):
    out = subprocess.run([nm, archive], capture_output=True, text=True, check=True).stdout
    defs, uses, cur = {}, {}, None
    for line in out.splitlines():
        if line.endswith(':') and ' ' not in line:
            cur = line[:-1].rsplit('/', 1)[-1].replace('src_core_', '').replace('.c.o', '.c')
            uses.setdefault(cur, set())
            continue
        f = line.split()
        if cur is None:
            continue
        if len(f) == 3 and f[1] in 'TDRBC':
            defs[f[2]] = cur
        elif len(f) == 2 and f[0] == 'U':
            uses[cur].add(f[1])
    return {n: {defs[u] for u in us if u in defs and defs[u] != n} for n, us in uses.items()}


def circles(g):
    index, low, stack, on, out, n = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = n[0]
        n[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g.get(v, ())):
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

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def main():
    g = graph(sys.argv[1], sys.argv[2])
    if len(g) < 10 or not g.get('params.c'):
        print('too few core objects read from %s: %s' % (sys.argv[2], sorted(g)))
        return 1
    bad = circles(g)
    for c in bad:
        print('circle between: ' + ', '.join(c))
        for f in c:
            print('  %s uses %s' % (f, ', '.join(sorted(set(g[f]) & set(c)))))
    print('%d core files, %d circles' % (len(g), len(bad)))
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
