"""A source file's scene graph, and the one way it becomes a :class:`~colossus.pipeline.model.SkinnedMesh`.

The node-graph readers (glTF, and every format assimp reads) describe what the file holds as a
:class:`Scene`: nodes with their rest local transforms, meshes (skinned or not) attached to
nodes, and animation channels with their own key times, values and interpolation.
:func:`~.build.build` then decides, in one place for every format:

* **which meshes move with the skeleton**: every skinned mesh, and every mesh whose node lies
  under a joint (rigid skinning through the hierarchy: bound with weight 1 to the nearest joint
  above it), unless ``--mesh`` names them;
* **the joints**: the union of every chosen skin's bones (several skins become one skeleton;
  several roots are fine in UsdSkel), plain nodes lying between two joints, and every *animated*
  node above a joint or on a rigid mesh's path, so that each joint's local motion is one node's
  own interpolated TRS (composing two animated nodes into one joint would not interpolate like
  the source between frames);
* **skeleton space** is the scene's world space; every vertex is placed there in the bind pose,
  so ``geom_bind`` is identity;
* **the frame grid**: every clip is sampled on one regular grid, ``fps`` frames per second (the
  caller's ``--fps``; else the first rate of :data:`GRID_RATES` on which every key of every clip
  falls; else the rate holding the most clips; else 30), from the frame at or before its first key
  to the frame at or after its last, time zero kept.  Each channel is sampled with its own
  interpolation (LINEAR: lerp, slerp for rotations; STEP; CUBICSPLINE Hermite), so every key that
  falls on the grid keeps its exact pose, and the first and last keys' poses are held.  A clip
  whose keys fall off the grid gets a resampling error bound (:func:`~.timeline._resampling_bound`).

Three modules: :mod:`.graph` (the records a reader fills, :func:`check_scene`, world
transforms), :mod:`.timeline` (channel sampling, the frame grid, the resampling bound) and
:mod:`.build` (:func:`~.build.build`, one function per step).  ``build`` is the module: the
readers import the function as ``from .scene.build import build``.
"""

from __future__ import annotations

from .graph import INTERPOLATIONS, Animation, Channel, Scene, SceneMesh, Skin, check_scene
from .timeline import DEFAULT_FPS, GRID_RATES, MAX_FRAMES, choose_fps, grid_frames, sample_channel

__all__ = ["Animation", "Channel", "Scene", "SceneMesh", "Skin", "INTERPOLATIONS", "check_scene",
           "GRID_RATES", "DEFAULT_FPS", "MAX_FRAMES", "choose_fps", "grid_frames", "sample_channel"]
