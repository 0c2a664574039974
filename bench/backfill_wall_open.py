#!/usr/bin/env python3
# Gives the job logs written before stop 63 their wall_open column (1: the wall is
# open, 0: closed; job::JobInputs::wall_open), by wall name: their walls are these
# eleven, and the test JobInputs.SayWhetherTheirWallIsOpen checks the engine's
# sim::is_closed_manifold says the same of each. A log that already has the column,
# or names another wall, is refused.
#
#   python3 bench/backfill_wall_open.py LOG.csv [LOG.csv ...]
import csv
import sys

OPEN = {'3dsmax_export_assimp.stl', 'funnel:r1=5,r2=30,h=40,segments=64',
        'sphere_with_hole_assimp.stl', 'teapot_trimesh.stl'}
CLOSED = {'box:x=2,y=1,z=1', 'box:x=20,y=20,z=20', 'cone:r1=20,r2=5,h=30,segments=32',
          'cylinder:r=10,h=30,segments=24', 'sphere:r=10,subdivisions=3', 'wall1', 'wall2'}

for path in sys.argv[1:]:
    rows = list(csv.reader(open(path, newline='')))
    head = rows[0]
    if 'wall_open' in head:
        sys.exit(f'{path}: already has wall_open')
    wall = head.index('wall')
    out = [head + ['wall_open']]
    for r in rows[1:]:
        if not r:
            continue
        if r[wall] not in OPEN | CLOSED:
            sys.exit(f'{path}: {r[wall]} is not among the walls this script knows')
        out.append(r + ['1' if r[wall] in OPEN else '0'])
    with open(path, 'w', newline='') as f:
        csv.writer(f, lineterminator='\n').writerows(out)
    print(path, len(out) - 1, 'rows')
