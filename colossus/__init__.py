"""colossus: deformable mesh colliders from rigged, animated characters, proven correct at every
instant of every clip.

The floors, each importing only those below it (``tests/test_layers.py`` enforces it)::

    colossus.runtime      load a collider, pose it, query it (numpy, numba, usd-core only)
    colossus.pipeline     read an export, bake, weld, orient, bind, parts, spheres, write
    colossus.validators   the rules, the reports and the every-instant proof
    colossus.render       pictures of an asset (pyvista/VTK, matplotlib: the ``render`` extra)
    colossus.cli          the ``colossus`` command line (``python -m colossus``)
    colossus.bench        ``colossus bench``: ratios against baselines run in the same process

The public entry points are here, imported on first use (a runtime-only install never loads the
importer)::

    from colossus import load_collider, import_asset, check_asset
"""

from ._version import __version__

__all__ = ["__version__", "load_collider", "import_asset", "check_asset"]

#: public name -> module that defines it (PEP 562: loaded on first access)
_LAZY = {"load_collider": "colossus.runtime", "ColliderError": "colossus.runtime",
         "import_asset": "colossus.pipeline.run", "check_asset": "colossus.validators"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'colossus' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
