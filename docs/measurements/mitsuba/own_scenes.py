"""Mitsuba 3 versions of stagelight's own test scenes (tests/scenes/glass_spheres.ron and
window_room.ron), written out by hand from the RON files: same triangles (quads split as
(a,b,c),(a,c,d); icospheres from gen_meshes.icosphere), same materials and camera.

Used for the references of docs/measurements/2026-11-25-metropolis.md: copy this file beside
../shared/mitsuba/ (it imports gen_meshes.py and scenes.py from there), make render_own.py from
render_refs.py by replacing its `import scenes` with `import own_scenes as scenes`, then
    python render_own.py glass_spheres --spp 1000000 --chunk 256 --budget 900 --out refs
The meshes are written under own/ beside this file. stagelight does not need any of this."""
import os
import mitsuba as mi
import gen_meshes as gm
from scenes import rgb, diffuse2, BLACK, GLASS, camera_to_world

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'own')


def conductor(alpha, c):
    return {'type': 'roughconductor', 'material': 'none', 'distribution': 'ggx', 'alpha': alpha,
            'specular_reflectance': rgb(c), 'sample_visible': True}


def quad(*p):
    return gm.Mesh().quad(*p)


def box(lo, hi):
    return gm.Mesh().box(lo, hi)


def glass_spheres():
    cam = ((0, 1.6, 4.5), (0, 0.55, 0), (0, 1, 0), 36.0, 96, 64)
    objs = [
        ('floor', quad((-3, 0, -2), (-3, 0, 3), (3, 0, 3), (3, 0, -2)), diffuse2((0.7, 0.7, 0.7)), None),
        ('back_wall', quad((-3, 0, -2), (3, 0, -2), (3, 3, -2), (-3, 3, -2)), diffuse2((0.6, 0.5, 0.4)), None),
        ('light', quad((-0.4, 2.5, -0.4), (0.4, 2.5, -0.4), (0.4, 2.5, 0.4), (-0.4, 2.5, 0.4)), BLACK, (30, 30, 30)),
        ('glass_sphere', gm.icosphere(3, (-0.65, 0.55, 0.2), 0.55), GLASS, None),
        ('mirror_sphere', gm.icosphere(3, (0.65, 0.55, 0.2), 0.55), conductor(0.01, (0.95, 0.95, 0.95)), None),
    ]
    return cam, objs


def window_room():
    cam = ((3.8, 1.8, 0.2), (0.8, 0.8, 2.3), (0, 1, 0), 65.0, 128, 96)
    wall, floor = diffuse2((0.75, 0.75, 0.72)), diffuse2((0.5, 0.4, 0.3))
    objs = [
        ('floor', quad((0, 0, 0), (4, 0, 0), (4, 0, 4), (0, 0, 4)), floor, None),
        ('ceiling', quad((0, 2.5, 0), (0, 2.5, 4), (4, 2.5, 4), (4, 2.5, 0)), wall, None),
        ('wall_x4', quad((4, 0, 0), (4, 0, 4), (4, 2.5, 4), (4, 2.5, 0)), wall, None),
        ('wall_z0', quad((0, 0, 0), (0, 2.5, 0), (4, 2.5, 0), (4, 0, 0)), wall, None),
        ('wall_z4', quad((0, 0, 4), (4, 0, 4), (4, 2.5, 4), (0, 2.5, 4)), wall, None),
        ('below', quad((0, 0, 0), (0, 1, 0), (0, 1, 4), (0, 0, 4)), wall, None),
        ('above', quad((0, 2, 0), (0, 2.5, 0), (0, 2.5, 4), (0, 2, 4)), wall, None),
        ('left', quad((0, 1, 0), (0, 2, 0), (0, 2, 1.5), (0, 1, 1.5)), wall, None),
        ('right', quad((0, 1, 2.5), (0, 2, 2.5), (0, 2, 4), (0, 1, 4)), wall, None),
        ('sun', quad((-2.2, 4, 1.8), (-1.8, 4, 1.8), (-1.8, 4, 2.2), (-2.2, 4, 2.2)), BLACK, (2000, 1900, 1700)),
        ('box', box((1.6, 0, 2.4), (2.4, 0.7, 3.2)), diffuse2((0.3, 0.45, 0.7)), None),
        ('copper_sphere', gm.icosphere(3, (1.1, 0.35, 1.9), 0.35), conductor(0.25, (0.95, 0.64, 0.54)), None),
    ]
    return cam, objs


def build(scene, spp=16):
    (o, t, u, fov, w, h), objs = {'glass_spheres': glass_spheres, 'window_room': window_room}[scene]()
    d = {'type': 'scene', 'integrator': {'type': 'path', 'max_depth': -1}}
    d['sensor'] = {
        'type': 'perspective', 'fov': fov, 'fov_axis': 'y', 'to_world': camera_to_world(o, t, u),
        'sampler': {'type': 'independent', 'sample_count': spp},
        'film': {'type': 'hdrfilm', 'width': w, 'height': h, 'pixel_format': 'rgb',
                 'component_format': 'float32', 'rfilter': {'type': 'box'}},
    }
    os.makedirs(os.path.join(OUT, scene), exist_ok=True)
    for name, mesh, bsdf, emit in objs:
        path = os.path.join(OUT, scene, name + '.ply')
        gm.write_ply(path, mesh.v, mesh.t, mesh.n)
        shape = {'type': 'ply', 'filename': path, 'face_normals': mesh.n is None, 'bsdf': bsdf}
        if emit:
            shape['emitter'] = {'type': 'area', 'radiance': rgb(emit)}
        d[name] = shape
    return d
