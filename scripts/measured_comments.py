#!/usr/bin/env python3
"""Non-test comment lines that carry a measurement (a percentage, seeds, AUROC, a "measured"
figure), which belong in docs/decisions/ with a one-line reference left in the code.
Usage: scripts/measured_comments.py [--list]"""
import pathlib, re, sys

PAT = re.compile(r'(\d ?%|\bseeds? \d|AUROC \d|[Mm]easured\b[^.;]*\d)')
root = pathlib.Path(__file__).resolve().parent.parent
hits = []
for p in sorted(root.glob('*/src/**/*.rs')) + sorted(root.glob('src/**/*.rs')):
    if 'target' in p.parts or p.name == 'tests.rs' or 'tests' in p.parts:
        continue
    in_test = False
    for n, line in enumerate(p.read_text().splitlines(), 1):
        s = line.strip()
        if s.startswith('#[cfg(test)]'):
            in_test = True  # the rest of the file is its test module
        if in_test or not s.startswith('//') or s.startswith('//!'):
            continue
        if PAT.search(s) and 'docs/decisions' not in s:
            hits.append(f'{p.relative_to(root)}:{n}: {s}')
if '--list' in sys.argv:
    print('\n'.join(hits))
print(f'comment lines with measurements: {len(hits)}')
