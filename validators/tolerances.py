"""Every tolerance and default of the validators in one place (after trimesh's ``ToleranceMesh``).

Lengths named ``*_RELATIVE`` are fractions of the model size: the diagonal of the bind-pose
bounding box of the collider's points, in stage units.
"""

from colossus.runtime import schema as _schema

#: Influence weights of a vertex must sum to 1 within this (absolute).
WEIGHT_SUM = 1e-4
#: Weights below ``-WEIGHT_NEGATIVE`` count as negative (float noise is tolerated).
WEIGHT_NEGATIVE = 1e-7
#: Default maximum number of influences per vertex (``--max-influences``).
MAX_INFLUENCES = 4
#: Two distinct vertices closer than this are unwelded duplicates.
WELD_RELATIVE = 1e-6
#: A triangle whose area is at most (this x model size)^2 is zero-area (COL204; the one value,
#: shared with the importer's ``degenerate`` stage, lives in ``runtime.schema``).
ZERO_AREA_RELATIVE = _schema.ZERO_AREA_RELATIVE
#: A vertex lies inside its sphere when its distance to the centre exceeds the radius by at most
#: ``CONTAIN_RELATIVE x model size + CONTAIN_RADIUS x radius`` (float32 skinning noise).
CONTAIN_RELATIVE = 1e-6
CONTAIN_RADIUS = 1e-5
#: A sphere is slack when its radius exceeds the tightest radius that holds on all frames by
#: more than this ratio (``slack_ratio`` option).
SLACK_RATIO = 1.5
#: Bind transforms agree with the composed rest transforms when every entry differs by at most
#: this times (1 + the entry's magnitude), translations scaled by the model size.
BIND_REST_RELATIVE = 1e-4
#: A bind transform is invertible when |det| of its 3x3 part exceeds this (and so are a rest
#: transform and a joint's posed transform on a clip's frame, COL318 / COL518).
MIN_DETERMINANT = 1e-12
#: An animated scale whose magnitude on an axis is below this counts as zero (COL518;
#: :data:`runtime.schema.MIN_SCALE`, the importer's limit too).
MIN_SCALE = 2.0 ** -22
#: Time codes are integers within this.
TIME_CODE_EPS = 1e-6
#: Frame-proof chunking: at most this many bytes of per-frame joint matrices at once.
CHUNK_BYTES = 32 * 1024 * 1024
#: ... and at most this many frames per chunk.
CHUNK_FRAMES = 256
#: ``--source``: the asset's motion must match the source's within this on every frame.
SOURCE_MOTION_RELATIVE = 1e-4
#: ``--source``: an asset vertex and a source vertex closer than this at the bind pose are the same.
SOURCE_MATCH_RELATIVE = 1e-5
#: A part's guide sphere (COL408) agrees with ``colossus:parts:*`` when, skinned by UsdSkel, its
#: centre lands within this x model size of the part's centre and its radius within this
#: fraction of the part's radius (the float32 values are written as they are stored).
GUIDE_RELATIVE = 1e-6
