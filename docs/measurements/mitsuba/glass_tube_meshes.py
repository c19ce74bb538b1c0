"""Meshes of tests/scenes/glass_tube.ron for glass_tube.xml (the same scene for Mitsuba 3):
the same triangles (a quad (a,b,c,d) is (a,b,c),(a,c,d); the icosphere from
../shared/mitsuba/gen_meshes.py, the construction of stagelight's Icosphere), written as PLY
files into glass_tube/ beside this file. Usage (gen_meshes.py on the path):
    PYTHONPATH=/work/shared/mitsuba python glass_tube_meshes.py"""
import os
import gen_meshes as gm

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'glass_tube')
Q = {
    'floor': ((-1.5, 0, -1.5), (-1.5, 0, 1.5), (1.5, 0, 1.5), (1.5, 0, -1.5)),
    'ceiling': ((-1.5, 2.5, -1.5), (1.5, 2.5, -1.5), (1.5, 2.5, 1.5), (-1.5, 2.5, 1.5)),
    'wall_zm': ((-1.5, 0, -1.5), (1.5, 0, -1.5), (1.5, 2.5, -1.5), (-1.5, 2.5, -1.5)),
    'wall_zp': ((-1.5, 0, 1.5), (-1.5, 2.5, 1.5), (1.5, 2.5, 1.5), (1.5, 0, 1.5)),
    'wall_xm': ((-1.5, 0, -1.5), (-1.5, 2.5, -1.5), (-1.5, 2.5, 1.5), (-1.5, 0, 1.5)),
    'wall_xp': ((1.5, 0, -1.5), (1.5, 0, 1.5), (1.5, 2.5, 1.5), (1.5, 2.5, -1.5)),
    'tube_xm': ((-0.15, 1.6, -0.15), (-0.15, 1.6, 0.15), (-0.15, 2.5, 0.15), (-0.15, 2.5, -0.15)),
    'tube_xp': ((0.15, 1.6, -0.15), (0.15, 2.5, -0.15), (0.15, 2.5, 0.15), (0.15, 1.6, 0.15)),
    'tube_zm': ((-0.15, 1.6, -0.15), (-0.15, 2.5, -0.15), (0.15, 2.5, -0.15), (0.15, 1.6, -0.15)),
    'tube_zp': ((-0.15, 1.6, 0.15), (0.15, 1.6, 0.15), (0.15, 2.5, 0.15), (-0.15, 2.5, 0.15)),
    'light': ((-0.1, 2.49, -0.1), (0.1, 2.49, -0.1), (0.1, 2.49, 0.1), (-0.1, 2.49, 0.1)),
}
os.makedirs(OUT, exist_ok=True)
for name, q in Q.items():
    m = gm.Mesh().quad(*q)
    gm.write_ply(os.path.join(OUT, name + '.ply'), m.v, m.t, None)
s = gm.icosphere(4, (0.0, 0.4, 0.0), 0.35)
gm.write_ply(os.path.join(OUT, 'sphere.ply'), s.v, s.t, s.n)
