"""Shapes and volumes: meshes and volumes in, densities to the core, completed meshes out.

- :mod:`wbcgrade.shape.mesh`: read, normalise, voxelise meshes; iso-surfaces.
- :mod:`wbcgrade.shape.volume`: ``.npy`` / NIfTI volumes and densities.
- :mod:`wbcgrade.shape.database`: mesh files voxelised in the unit frame, placed there.
- :mod:`wbcgrade.shape.projection`: a density's barycentric coordinates on a database.
- :mod:`wbcgrade.shape.complete`: completing a partial shape (``complete_shape``).
- :mod:`wbcgrade.shape.surface`: the completed surface (the input united with what is added).
- :mod:`wbcgrade.shape.sheets`: contact sheets of a completion and of a projection.
- :mod:`wbcgrade.shape.memory`: what a fit needs in memory.
- :mod:`wbcgrade.shape.render`: PNG views without a plotting library.
- :mod:`wbcgrade.shape.workflow`: what ``wbcgrade shape complete/project`` run.

Layers and data flow: docs/architecture.md.
"""
