"""colossus import pipeline: Blender export in, USD collider asset out.

The stages are chained in :func:`pipeline.run.import_asset`; readers are registered by file
extension in :mod:`pipeline.readers`.
"""

__version__ = "0.1.0"
