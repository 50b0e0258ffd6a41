"""Procedural test objects built by constructive solid geometry (manifold3d), metres.

Analogues of the paper's objects: a giraffe-like quadruped (Fig. 8: a torso too thick for
the ARMAR-III hand at scale 1.0, thin legs and neck) and a mug (Fig. 10: a hollow body
wider than the hand, a handle). Every builder returns one watertight ``trimesh.Trimesh``.
"""

import manifold3d
import numpy as np
import trimesh

_SEGMENTS = 96


def _to_trimesh(solid):
    mesh = solid.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties[:, :3], np.float64),
                           np.asarray(mesh.tri_verts, np.int64), process=True)


def _limb(start, end, radius):
    """A cylinder with rounded ends from ``start`` to ``end`` (metres)."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    axis = end - start
    length = float(np.linalg.norm(axis))
    tilt = np.degrees(np.arccos(np.clip(axis[2] / length, -1, 1)))
    heading = np.degrees(np.arctan2(axis[1], axis[0]))
    body = manifold3d.Manifold.cylinder(length, radius, radius, _SEGMENTS)
    body = body + manifold3d.Manifold.sphere(radius, _SEGMENTS) + \
        manifold3d.Manifold.sphere(radius, _SEGMENTS).translate([0, 0, length])
    return body.rotate([0, tilt, 0]).rotate([0, 0, heading]).translate(start)


def quadruped():
    """Giraffe-like animal, about 1.1 m long: ellipsoid torso 0.60 x 0.26 x 0.26 m (far thicker
    than 9.4 cm), legs and tail of radius 3 cm, neck of radius 3.5 cm, a small head."""
    torso = manifold3d.Manifold.sphere(1.0, _SEGMENTS).scale([0.30, 0.13, 0.13]).translate([0, 0, 0.75])
    parts = [torso]
    for x in (-0.2, 0.2):
        for y in (-0.07, 0.07):
            parts.append(_limb([x, y, 0.05], [x, y, 0.72], 0.03))
    parts.append(_limb([0.22, 0, 0.8], [0.45, 0, 1.25], 0.035))                      # neck
    parts.append(_limb([-0.28, 0, 0.78], [-0.45, 0, 0.55], 0.02))                   # tail
    parts.append(manifold3d.Manifold.sphere(1.0, _SEGMENTS).scale([0.09, 0.045, 0.045]).translate([0.5, 0, 1.28]))
    return _to_trimesh(manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add))


def mug():
    """Mug 12 cm tall: body of outer radius 5 cm (10 cm across, wider than 9.4 cm), 6 mm wall,
    8 mm base, open top; a D-shaped handle of 8 mm radius on the +x side."""
    outer = manifold3d.Manifold.cylinder(0.12, 0.05, 0.05, _SEGMENTS)
    cavity = manifold3d.Manifold.cylinder(0.12, 0.044, 0.044, _SEGMENTS).translate([0, 0, 0.008])
    ring = manifold3d.CrossSection.circle(0.008, 48).translate([0.035, 0]).revolve(_SEGMENTS)
    handle = ring.rotate([90, 0, 0]).translate([0.05, 0, 0.06])
    return _to_trimesh(outer + handle - cavity)


BUILDERS = {"quadruped": quadruped, "mug": mug}
