"""COL0xx: reading the asset and running the checker.  These findings are made by the runner
(:mod:`validators.runner`), not by a check function."""

from ..registry import rule

rule("COL001", "asset-unreadable", "error",
     "An asset usd-core cannot open (corrupt, truncated, not USD) cannot be checked at all.",
     doc="""What: usd-core could not open the file, or reading its prims raised.
Why: a corrupt or truncated asset must fail the gate by itself, without stopping the others.
Example: random bytes saved as `boss.usdc`; a `.usda` cut off in the middle of a prim.""")(None)

rule("COL002", "checker-error", "error",
     "A rule crashed on this asset: the asset is unproven, and the checker needs a fix.",
     doc="""What: a rule raised an exception; the finding names the rule and the exception.
Why: kept apart from failed checks (flake8's PluginExecutionFailed): the asset is not proven.
Example: a rule meets a value type it did not expect.""")(None)

rule("COL003", "path-missing", "error",
     "A path given to the validator does not exist or cannot be read (exit status 2).",
     doc="""What: the path does not exist or cannot be read.
Why: a CI job that gates a path that is not there is misconfigured; `colossus validate` exits 2.
Example: `colossus validate assets/typo.usda`.""")(None)

rule("COL004", "external-reference", "error",
     "The asset names another file (a sublayer, reference, payload or value clip): a collider is one self-contained layer.",
     doc="""What: the asset's layer names an asset path: a sublayer, a reference or payload to another file, a
value clip, an asset-valued attribute.  They are read from the layer alone (`Sdf`), nothing is composed,
and the asset is not opened any further: no file it names is ever read.
Why: an asset colossus writes has no composition arcs; one that has them was changed after the import,
and what it would pull in (`/etc/passwd`, a FIFO that blocks the reader for ever, another asset) is not
what was validated.  `colossus validate` runs on untrusted pull requests.
Example: `subLayers = [@/dev/zero@]`; `references = @../other.usda@</Boss>`.""")(None)
