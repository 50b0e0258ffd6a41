"""Mass properties of a closed, outward-oriented triangle mesh of uniform density (metres, kg)."""

import numpy as np


def mesh_volume(vertices, faces):
    """Volume (m^3) of a closed, outward-oriented mesh (signed tetrahedra)."""
    corners = np.asarray(vertices, float)[np.asarray(faces)]
    return float(np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0)


def centre_of_mass(vertices, faces):
    """Centre of mass (3,) of a closed mesh of uniform density, from signed tetrahedra."""
    corners = vertices[faces]
    volumes = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2]))
    return (volumes[:, None] * corners.sum(axis=1)).sum(axis=0) / (4.0 * volumes.sum())


def torque_reference(vertices, faces):
    """The grasp quality's torque reference of a closed mesh: its centre of mass (3,) and the
    length (m) dividing torques, the largest distance of a vertex from it (GraspIt, Dex-Net)."""
    vertices = np.asarray(vertices, np.float64)
    centre = centre_of_mass(vertices, np.asarray(faces))
    return centre, float(np.linalg.norm(vertices - centre, axis=1).max())


def inertia(vertices, faces, mass_kg):
    """(centre (3,), inertia (6,) ``ixx iyy izz ixy ixz iyz`` about the centre, kg m^2) of a
    closed mesh of uniform density weighing ``mass_kg`` (trimesh's integrals)."""
    import trimesh

    mesh = trimesh.Trimesh(np.asarray(vertices, float), np.asarray(faces), process=False)
    tensor = mesh.moment_inertia * (mass_kg / mesh.volume)  # trimesh: unit density, about the centre of mass
    moments = [tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1], tensor[0, 2], tensor[1, 2]]
    return np.asarray(mesh.center_mass, float), np.asarray(moments, float)
