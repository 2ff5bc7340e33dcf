"""COL7xx proxy: a simplified collision mesh (``colossus import --target-faces/--max-deviation``)
and the deviation bound it carries."""

from __future__ import annotations

import math

from colossus.runtime import schema

from ..registry import hit, rule


def _proxy(asset):
    """``(is_proxy, data)``: whether the asset says it is a simplified proxy, and its
    ``customData["colossus"]["proxy"]`` dictionary (or None)."""
    prov = asset.mesh.GetCustomDataByKey(schema.PROVENANCE_KEY)
    prov = prov if isinstance(prov, dict) else {}
    data = asset.mesh.GetCustomDataByKey(schema.PROXY_KEY)
    settings = prov.get("settings") if isinstance(prov.get("settings"), dict) else {}
    asked = any(settings.get(k) not in (None, "") for k in ("target_faces", "max_deviation"))
    return bool(asked or isinstance(data, dict)), (data if isinstance(data, dict) else None)


@rule("COL701", "proxy-deviation", "error",
      "A simplified proxy records its deviation from the full skinned mesh, within --max-deviation when given.",
      needs=("mesh",))
def proxy_deviation(asset, ctx):
    """What: an asset imported with `--target-faces` or `--max-deviation` stores
    `colossus:proxy:sourceFaces` (at least its own face count) and `colossus:proxy:maxDeviation`
    (a finite length >= 0, stage units) in its provenance; with `colossus validate
    --max-deviation D` (stage units, or `D%` of the model size) the stored deviation must not
    exceed D.  An asset that is not a proxy is the full mesh (deviation 0) and passes.
    Why: a proxy is only as good as its distance from the body a player sees; the gate must
    refuse one that is unmeasured or strays further than the game allows.
    Example: a proxy whose provenance lost `maxDeviation`; a proxy 0.05 m off validated with
    `--max-deviation 0.02`."""
    is_proxy, data = _proxy(asset)
    if not is_proxy:
        return
    path = str(asset.mesh.GetPath())
    dev = asset.mesh.GetCustomDataByKey(schema.PROXY_MAX_DEVIATION)
    faces = asset.mesh.GetCustomDataByKey(schema.PROXY_SOURCE_FACES)
    if data is None or dev is None:
        yield hit(f"a simplified proxy without {schema.PROXY_MAX_DEVIATION} in its customData", prim=path)
        return
    try:
        dev = float(dev)
    except (TypeError, ValueError):
        dev = math.nan
    if not (math.isfinite(dev) and dev >= 0):
        yield hit(f"{schema.PROXY_MAX_DEVIATION} is {dev!r}, expected a finite length >= 0", prim=path)
        return
    if not isinstance(faces, int) or faces < len(asset.tris):
        yield hit(f"{schema.PROXY_SOURCE_FACES} is {faces!r}, expected an integer >= the proxy's "
                  f"{len(asset.tris)} faces", prim=path)
    limit = ctx.max_deviation
    if limit is not None:
        from colossus.pipeline.options import resolve_max_deviation
        allowed = resolve_max_deviation(limit, asset.model_size)
        if dev > allowed:
            where = " ".join(str(asset.mesh.GetCustomDataByKey(k)) for k in (schema.PROXY_WORST_CLIP,
                                                                             schema.PROXY_WORST_FRAME)
                             if asset.mesh.GetCustomDataByKey(k) is not None)
            yield hit(f"the proxy strays up to {dev:.6g} from the full skinned mesh, more than --max-deviation "
                      f"{allowed:.6g}" + (f" (worst at {where})" if where else ""), sort_key=dev - allowed,
                      excess=dev - allowed, prim=path)
