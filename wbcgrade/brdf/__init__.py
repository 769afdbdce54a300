"""Reflectance (BRDF): measured BRDFs in, histograms on the hemisphere to the core, fits out.

- :mod:`wbcgrade.brdf.sampling`: hemisphere directions (spherical Fibonacci),
  squared geodesic cost, the core geometry and its default gamma.
- :mod:`wbcgrade.brdf.merl`: the MERL ``.binary`` format (read, write,
  half/difference angles, resampling onto the hemisphere).
- :mod:`wbcgrade.brdf.analytic`: GGX conductors and plastics, Ward, Lambert;
  the deterministic synthetic database.
- :mod:`wbcgrade.brdf.sampled`: sampled BRDFs: interpolation, PSNR, decimation.
- :mod:`wbcgrade.brdf.io`: BRDF files (``.binary``, ``.npz``) and database folders.
- :mod:`wbcgrade.brdf.fit`: barycentric coordinates of a (sparse) measurement.
- losses restricted to the kept measurements live in the core (:mod:`wbcgrade.core.masked`).
- :mod:`wbcgrade.brdf.render`: spheres lit by a directional light, as PNG.
- :mod:`wbcgrade.brdf.workflow`: what ``wbcgrade brdf synth/fit`` run (files in, files out).
- :mod:`wbcgrade.brdf.defaults`: default settings (light: read by ``--help``).

Layers and data flow: docs/architecture.md.
"""
