"""Reference renders: the scene mipray sees, rendered by Mitsuba 3, and the comparison.

- :mod:`mipray.reference.mitsuba`: exports a USD stage to a Mitsuba 3 scene
  (``scalar_rgb`` variant) exactly as mipray's scene delegate hands it to the
  renderer — the same triangle meshes, camera, lights and materials — and
  renders it.
- :mod:`mipray.reference.scenes`: the comparison scenes, built in memory.
- :mod:`mipray.reference.compare`: renders each scene with both renderers,
  measures the RMSE between them against the noise their sample counts
  explain, and writes ``docs/mitsuba-comparison.md``
  (``python -m mipray.reference.compare``).

Mitsuba is an optional dependency (``pip install mitsuba``); importing this
package does not need it.
"""
