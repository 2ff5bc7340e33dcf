"""colossus import pipeline: Blender export in, USD collider asset out.

The stages are chained in :func:`pipeline.run.import_asset`; readers are registered by file
extension in :mod:`pipeline.readers`.
"""

from colossus._version import __version__  # noqa: F401  (one version, written once)
