"""Procedural test objects built by constructive solid geometry (manifold3d), metres.

Analogues of the paper's objects: a giraffe-like quadruped (Fig. 8: a torso too thick for
the ARMAR-III hand at scale 1.0, thin legs and neck), a mug (Fig. 10: a hollow body wider
than the hand, a handle), a tea kettle, a vase, a table, a chair, a pair of glasses, a bust
on a neck and an octopus. Every builder returns one watertight ``trimesh.Trimesh``; the
sizes in the docstrings are the real-world ones they are built at.
"""

import manifold3d
import numpy as np
import trimesh

_SEGMENTS = 96


def _to_trimesh(solid):
    mesh = solid.to_mesh()
    return trimesh.Trimesh(
        np.asarray(mesh.vert_properties[:, :3], np.float64), np.asarray(mesh.tri_verts, np.int64), process=True
    )


def _limb(start, end, radius):
    """A cylinder with rounded ends from ``start`` to ``end`` (metres)."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    axis = end - start
    length = float(np.linalg.norm(axis))
    tilt = np.degrees(np.arccos(np.clip(axis[2] / length, -1, 1)))
    heading = np.degrees(np.arctan2(axis[1], axis[0]))
    body = manifold3d.Manifold.cylinder(length, radius, radius, _SEGMENTS)
    body = (
        body
        + manifold3d.Manifold.sphere(radius, _SEGMENTS)
        + manifold3d.Manifold.sphere(radius, _SEGMENTS).translate([0, 0, length])
    )
    return body.rotate([0, tilt, 0]).rotate([0, 0, heading]).translate(start)


def quadruped():
    """Giraffe-like animal, about 1.1 m long: ellipsoid torso 0.60 x 0.26 x 0.26 m (far thicker
    than 9.4 cm), legs and tail of radius 3 cm, neck of radius 3.5 cm, a small head."""
    torso = manifold3d.Manifold.sphere(1.0, _SEGMENTS).scale([0.30, 0.13, 0.13]).translate([0, 0, 0.75])
    parts = [torso]
    for x in (-0.2, 0.2):
        for y in (-0.07, 0.07):
            parts.append(_limb([x, y, 0.05], [x, y, 0.72], 0.03))
    parts.append(_limb([0.22, 0, 0.8], [0.45, 0, 1.25], 0.035))  # neck
    parts.append(_limb([-0.28, 0, 0.78], [-0.45, 0, 0.55], 0.02))  # tail
    parts.append(manifold3d.Manifold.sphere(1.0, _SEGMENTS).scale([0.09, 0.045, 0.045]).translate([0.5, 0, 1.28]))
    return _to_trimesh(manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add))


def mug(radius=0.05):
    """Mug 12 cm tall: body of outer ``radius`` (m; 5 cm: 10 cm across, wider than 9.4 cm), 6 mm
    wall, 8 mm base, open top; a D-shaped handle of 8 mm radius on the +x side."""
    outer = manifold3d.Manifold.cylinder(0.12, radius, radius, _SEGMENTS)
    cavity = manifold3d.Manifold.cylinder(0.12, radius - 0.006, radius - 0.006, _SEGMENTS).translate([0, 0, 0.008])
    ring = manifold3d.CrossSection.circle(0.008, 48).translate([0.035, 0]).revolve(_SEGMENTS)
    handle = ring.rotate([90, 0, 0]).translate([radius, 0, 0.06])
    return _to_trimesh(outer + handle - cavity)


def _box(size, centre):
    return manifold3d.Manifold.cube(size, True).translate(centre)


def _revolved(profile):
    """A solid of revolution about z from a closed (r, z) polygon, metres."""
    return manifold3d.CrossSection([np.asarray(profile, float)]).revolve(_SEGMENTS)


def kettle():
    """Tea kettle about 23 cm long, 21 cm tall: a closed body of radius 8 cm (wider than both
    hands) on a flat base, a lid knob, a spout of radius 1.2-1.8 cm rising at 45 deg on -x and a
    handle arching over the top (8 mm radius) for a grasp from above."""
    body = _revolved([(0, 0), (0.07, 0), (0.08, 0.02), (0.08, 0.10), (0.06, 0.15), (0.03, 0.16), (0, 0.16)])
    knob = manifold3d.Manifold.sphere(0.012, _SEGMENTS).translate([0, 0, 0.165])
    spout = manifold3d.Manifold.cylinder(0.11, 0.018, 0.012, _SEGMENTS).rotate([0, -45, 0]).translate([-0.06, 0, 0.05])
    handle = manifold3d.CrossSection.circle(0.008, 48).translate([0.07, 0]).revolve(_SEGMENTS, 180)
    handle = handle.rotate([90, 0, 0]).translate([0, 0, 0.13])
    return _to_trimesh(manifold3d.Manifold.batch_boolean([body, knob, spout, handle], manifold3d.OpType.Add))


def vase():
    """Amphora-like vase 25 cm tall, 21.6 cm across its handles, hollow with a 4 mm wall and open
    top: a 6 cm base radius swelling to 9 cm, a 3 cm neck and a flared lip of 4.5 cm. Two
    handles of 8 mm radius on +-x leave the neck at 21 cm, run down 10 cm from the axis and
    enter the shoulder at 14 cm. The hollow body is too thick to grasp and its walls are
    plates, so the handles are where both hands grasp it (Fig. 10)."""
    outside = [(0, 0), (0.06, 0), (0.09, 0.08), (0.07, 0.15), (0.03, 0.20), (0.03, 0.23), (0.045, 0.25), (0, 0.25)]
    inside = [
        (0, 0.006),
        (0.056, 0.006),
        (0.086, 0.08),
        (0.066, 0.15),
        (0.026, 0.20),
        (0.026, 0.23),
        (0.041, 0.2501),
        (0, 0.2501),
    ]
    parts = [_revolved(outside)]
    for side in (-1, 1):
        corners = [(0.028 * side, 0, 0.21), (0.10 * side, 0, 0.21), (0.10 * side, 0, 0.14), (0.065 * side, 0, 0.14)]
        parts += [_limb(start, end, 0.008) for start, end in zip(corners, corners[1:])]
    return _to_trimesh(manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add) - _revolved(inside))


def table():
    """Side table 60 x 40 cm, 45 cm tall: a 2.5 cm top (a plate to the hands: rims only) on four
    square 4 cm legs."""
    parts = [_box([0.60, 0.40, 0.025], [0, 0, 0.4375])]
    for x in (-0.26, 0.26):
        for y in (-0.16, 0.16):
            parts.append(_box([0.04, 0.04, 0.43], [x, y, 0.215]))
    return _to_trimesh(manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add))


def chair():
    """Chair 42 x 42 cm, seat at 45 cm, back to 90 cm: legs of radius 1.5 cm, a 3 cm seat, a
    backrest of two uprights and a 6 cm rail."""
    parts = [_box([0.42, 0.42, 0.03], [0, 0, 0.45])]
    for x in (-0.18, 0.18):
        for y in (-0.18, 0.18):
            parts.append(_limb([x, y, 0.015], [x, y, 0.45], 0.015))
        parts.append(_limb([x, 0.19, 0.46], [x, 0.2, 0.88], 0.015))
    parts.append(_box([0.40, 0.025, 0.06], [0, 0.2, 0.85]))
    return _to_trimesh(manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add))


def glasses():
    """Glasses 14 cm wide: two round rims (2.4 cm inner radius, 2.5 mm wire), a bridge and two
    15 cm temples folded straight back."""
    rim = manifold3d.CrossSection.circle(0.0025, 24).translate([0.0265, 0]).revolve(_SEGMENTS)
    parts = [rim.rotate([90, 0, 0]).translate([x, 0, 0]) for x in (-0.033, 0.033)]
    parts.append(_limb([-0.009, 0, 0.012], [0.009, 0, 0.012], 0.0025))
    for x in (-0.0595, 0.0595):
        parts.append(_limb([x, 0, 0.01], [x * 1.15, 0.15, 0.0], 0.0025))
    return _to_trimesh(manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add))


def bust():
    """Bust 40 cm tall: shoulders 36 x 16 x 12 cm, a neck of radius 5.5 cm (11 cm across: too
    wide for ARMAR-III, fine for the Barrett hand), a head 16 x 19 x 23 cm."""
    shoulders = manifold3d.Manifold.sphere(1.0, _SEGMENTS).scale([0.18, 0.08, 0.07]).translate([0, 0, 0.07])
    neck = manifold3d.Manifold.cylinder(0.12, 0.055, 0.055, _SEGMENTS).translate([0, 0, 0.10])
    head = manifold3d.Manifold.sphere(1.0, _SEGMENTS).scale([0.08, 0.095, 0.115]).translate([0, 0.01, 0.285])
    return _to_trimesh(shoulders + neck + head)


def octopus():
    """Octopus 60 cm across: a mantle of radius 7-9 cm and eight arms tapering from 2 to 0.8 cm
    radius that leave the body and curl down to the ground."""
    mantle = manifold3d.Manifold.sphere(1.0, _SEGMENTS).scale([0.08, 0.08, 0.09]).translate([0, 0, 0.12])
    parts = [mantle]
    for arm in range(8):
        heading = 2 * np.pi * arm / 8
        direction = np.array([np.cos(heading), np.sin(heading), 0.0])
        points = [
            direction * 0.05 + [0, 0, 0.06],
            direction * 0.15 + [0, 0, 0.05],
            direction * 0.24 + [0, 0, 0.02],
            direction * 0.30 + [0, 0, 0.01],
        ]
        for (start, end), radius in zip(zip(points, points[1:]), (0.02, 0.014, 0.008)):
            parts.append(_limb(start, end, radius))
    return _to_trimesh(manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add))


BUILDERS = {
    "quadruped": quadruped,
    "mug": mug,
    "kettle": kettle,
    "vase": vase,
    "table": table,
    "chair": chair,
    "glasses": glasses,
    "bust": bust,
    "octopus": octopus,
}
