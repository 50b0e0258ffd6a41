"""The object's geometry, paper sections II-III: meshes and the catalogue, surface samples, the
medial axis and its spheres (MAT), the sphere grid, the symmetry classes (neighbourhood PCA),
concavities, the grasp candidates built on them, and exact queries on the mesh.

Nothing here knows the trial engine, the physics checks or the outputs: the geometry stages
(``sample`` to ``candidates``) depend on this package, :mod:`pipeline.hands` and the plumbing only.
"""
