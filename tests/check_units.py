#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""The core scales values between reduced and SI units in one place.

vafm/params.h says conversion lives in units.c: outside it the core's files scale a value only through
the vafm_scale_<quantity>_si / _red helpers declared with vafm_scale in include/vafm/units.h. This reads
every file of src/core, finds the names it gives vafm_scale values (declarations such as `vafm_scale sc`,
`const vafm_scale *sc`) and fails on any direct read of a scale factor through them (`sc->length_m`,
`nm.sc.time_s`, ...). Usage: check_units.py SRC_CORE_DIR
"""
import pathlib
import re
import sys

FIELDS = r'(length_m|time_s|force_N|energy_J|speed_m_per_s|stiffness_N_per_m)'
DECL = re.compile(r'\bvafm_scale\s+(?:const\s+)?\*?\s*(?:const\s+)?([A-Za-z_]\w*)\s*[;=,)]')
ALLOWED = {'units.c'}  # the conversions themselves


def offences(src):
    names = set()
    for f in src:
        names.update(DECL.findall(f.read_text(encoding='utf-8')))
    names.discard('vafm_units_scale')
    if not names:
        return [], names
    use = re.compile(r'\b(?:' + '|'.join(sorted(names)) + r')\s*(?:\.|->)\s*' + FIELDS + r'\b'
                     r'|\bvafm_units_scale\s*\([^;]*?\)\s*\.\s*' + FIELDS + r'\b')
    out = []
    for f in src:
        if f.name in ALLOWED:
            continue
        for n, line in enumerate(f.read_text(encoding='utf-8').splitlines(), 1):
            if use.search(line):
                out.append(f'{f}:{n}: {line.strip()}')
    return out, names


def main():
    core = pathlib.Path(sys.argv[1])
    src = sorted(p for p in core.iterdir() if p.suffix in ('.c', '.h'))
    if not src:
        print(f'no sources under {core}')
        return 1
    out, names = offences(src)
    if 'sc' not in names:
        print('found no vafm_scale declaration named sc (internal.h\'s vafm_numerics.sc): the check reads nothing')
        return 1
    for o in out:
        print(o)
    if out:
        print(f'{len(out)} direct use(s) of a vafm_scale factor outside units.c: use vafm_scale_<quantity>_si/_red '
              '(include/vafm/units.h), keeping the site\'s operation (x * f -> _si, x / f -> _red)')
        return 1
    print(f'units: {len(src)} files of the core scale through units.h\'s helpers only')
    return 0


if __name__ == '__main__':
    sys.exit(main())
