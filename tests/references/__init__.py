"""Independent references for character motion, one per source format (test support).

Nothing here imports the project (``pipeline``, ``validators``, ``runtime``): only numpy, scipy,
pxr, trimesh and the standard library, so the importer is judged against something it did not
compute.

* :mod:`.gltf_eval` -- a glTF 2.0 evaluator written from the specification.
* :mod:`.usd_eval` -- UsdSkel's own skinning of a USD source.
* :mod:`.fbx_truth` -- Maya's deformed meshes shipped with the ufbx test files.
* :mod:`.compare` -- skins a colossus asset with plain usd-core and compares it with a reference.
* :mod:`.diagnose` -- the command-line table over the corpus
  (``.venv/bin/python -m tests.references.diagnose``).
"""
