"""Shapes and volumes: meshes and volumes in, densities to the core, completed meshes out.

- :mod:`wbcgrade.shape.mesh`: read, normalise, voxelise meshes; iso-surfaces.
- :mod:`wbcgrade.shape.volume`: ``.npy`` / NIfTI volumes and densities.
- :mod:`wbcgrade.shape.complete`: completion and projection onto a database.
- :mod:`wbcgrade.shape.render`: PNG views without a plotting library.
- :mod:`wbcgrade.shape.workflow`: what ``wbcgrade shape complete/project`` run.

Layers and data flow: docs/architecture.md.
"""
