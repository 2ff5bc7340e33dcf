"""Scripted runs of the character controller: what ``colossus play --script FILE.json`` plays.

A script is a JSON object; every key is optional except ``steps``:

.. code-block:: json

    {
      "clip": "walk",
      "rate": 60,
      "loop": true,
      "radius": 0.035,
      "start": "top",
      "drop": 0.15,
      "floor": "auto",
      "controller": {"max_slope": 40, "hold_speed": 0.8},
      "steps": [
        {"wait": 1.0},
        {"walk": [1, 0, 0], "for": 1.5},
        {"jump": true, "walk": [1, 0, 0]},
        {"grab": 3.0, "walk": [0, 1, 0]}
      ]
    }

=============  ===========================  ====================================================
key            default                      meaning
=============  ===========================  ====================================================
``clip``       the asset's first clip       clip to play (``play --clip`` overrides it)
``rate``       60                           controller steps per second
``loop``       true                         the clip restarts when it ends (a walk cycle loops
                                            seamlessly); false holds its last frame
``radius``     ``play --radius`` (0.035)    player radius, a fraction of the model size
``start``      ``"top"``                    ``"top"``: above the most upward-facing spot near the
                                            middle of the model; or ``[x, y, z]`` in stage space
``drop``       0.15 (``"top"``), 0 (xyz)    height above the start, a fraction of the model size
``floor``      null                         a static terrain plane: null none, a height along up
                                            (stage units), or ``"auto"``: the clip's lowest point
``controller`` {}                           :class:`~runtime.controller.CharacterController`
                                            keyword parameters (stage units and seconds)
``steps``      (required)                   the intents, played in order (below)
=============  ===========================  ====================================================

Steps (durations in seconds, directions stage-space ``[x, y, z]`` of length <= 1, the fraction of
the state's speed; see :class:`~runtime.controller.Intent`):

* ``{"wait": S}`` - no intent for S seconds;
* ``{"walk": [x, y, z], "for": S}`` - move for S seconds;
* ``{"jump": true}`` or ``{"jump": true, "walk": [x, y, z]}`` - one step that takes off;
* ``{"grab": S}`` or ``{"grab": S, "walk": [x, y, z]}`` - hold on for S seconds (climbing
  while it moves).

A script that cannot be used raises :class:`ScriptError` (one line naming the file and the
problem).  Library code only: no printing; ``runtime.cli`` drives it and renders.
"""

from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass, field

import numpy as np

from .collider import Collider
from .controller import STANDING, STATES, CharacterController, Intent
from .errors import ColossusError, one_line

#: Longest script, in controller steps (at 60 steps per second: about 28 minutes).
MAX_STEPS = 100_000
ACTIONS = ("wait", "walk", "for", "jump", "grab")
TOP_KEYS = ("clip", "rate", "loop", "radius", "start", "drop", "floor", "controller", "steps")


class ScriptError(ColossusError):
    """A play script cannot be used (one-line message naming the file)."""


@dataclass
class Script:
    """A parsed play script (see the module docstring); ``intents`` has one entry per step."""

    intents: list
    clip: str | None = None
    rate: float = 60.0
    loop: bool = True
    radius: float | None = None
    start: object = "top"
    drop: float | None = None
    floor: object = None
    controller: dict = field(default_factory=dict)
    source: str = "<script>"

    @property
    def seconds(self) -> float:
        return len(self.intents) / self.rate


@dataclass
class Run:
    """The record of a scripted run, one row per controller step.

    times (N,) float64 time codes of the pose each step ended on, seconds (N,) since the start,
    states (N,) str, positions (N, 3) float64, triangles (N,) int64 deepest contact's triangle
    (-1 none or the terrain), penetration (N,) and slip (N,) stage units, energy (N,),
    on_floor (N,) bool, pushed (N,) bool: the moving body pushed the player that step."""

    clip: str
    radius: float
    rate: float
    times: np.ndarray
    seconds: np.ndarray
    states: np.ndarray
    positions: np.ndarray
    triangles: np.ndarray
    penetration: np.ndarray
    slip: np.ndarray
    energy: np.ndarray
    on_floor: np.ndarray
    floor: float | None = None
    pushed: np.ndarray | None = None

    def __post_init__(self):
        if self.pushed is None:
            self.pushed = np.zeros(len(self.times), dtype=bool)

    @property
    def grounded(self) -> np.ndarray:
        """(N,) bool: standing."""
        return self.states == STANDING

    @property
    def landed_at(self) -> float | None:
        """Time code of the first step that ends standing (None: never)."""
        g = np.nonzero(self.grounded)[0]
        return float(self.times[g[0]]) if len(g) else None

    @property
    def max_penetration(self) -> float:
        return float(self.penetration.max()) if len(self.penetration) else 0.0

    @property
    def max_slip(self) -> float:
        return float(self.slip.max()) if len(self.slip) else 0.0

    def state_counts(self) -> dict:
        """{state: steps} for the states that occur, in :data:`STATES` order."""
        return {s: int((self.states == s).sum()) for s in STATES if (self.states == s).any()}


# -- parsing -----------------------------------------------------------------------------------


def load_script(path) -> Script:
    """Read and check a script file; raises :class:`ScriptError` (one line) on any problem."""
    name = os.fspath(path)
    try:
        with open(name, encoding="utf-8") as fh:
            text = fh.read()
    except FileNotFoundError:
        raise ScriptError(f"{name}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ScriptError(f"{name}: cannot read: {one_line(e)}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise ScriptError(f"{name}: not JSON: {e.msg} at line {e.lineno} column {e.colno}") from None
    return parse_script(data, name)


def parse_script(data, source="<script>") -> Script:
    """Check a script already decoded from JSON (a dict); raises :class:`ScriptError`."""

    def bad(msg):
        return ScriptError(f"{source}: {msg}")

    if not isinstance(data, dict):
        raise bad(f"expected a JSON object with \"steps\", got {type(data).__name__}")
    unknown = [k for k in data if k not in TOP_KEYS]
    if unknown:
        raise bad(f"unknown key {unknown[0]!r} (expected {', '.join(TOP_KEYS)})")
    if "steps" not in data:
        raise bad("no \"steps\" list")
    rate = _number(data.get("rate", 60), "rate", bad, low=1.0, high=10_000.0)
    loop = data.get("loop", True)
    if not isinstance(loop, bool):
        raise bad(f"loop must be true or false, got {loop!r}")
    clip = data.get("clip")
    if clip is not None and not isinstance(clip, str):
        raise bad(f"clip must be a clip name, got {clip!r}")
    radius = data.get("radius")
    if radius is not None:
        radius = _number(radius, "radius", bad, low=0.001, high=0.5)
    start = data.get("start", "top")
    if start != "top":
        start = tuple(_vector(start, "start", bad, unit=False))
    drop = data.get("drop")
    if drop is not None:
        drop = _number(drop, "drop", bad, low=0.0, high=100.0)
    floor = data.get("floor")
    if floor is not None and floor != "auto":
        floor = _number(floor, "floor", bad)
    ctrl = data.get("controller", {})
    if not isinstance(ctrl, dict):
        raise bad(f"controller must be an object of CharacterController parameters, got {ctrl!r}")
    allowed = _controller_keywords()
    for k, v in ctrl.items():
        if k not in allowed:
            raise bad(f"controller: unknown parameter {k!r} (expected one of {', '.join(allowed)})")
        if k == "floor":
            raise bad("controller: give the terrain as the script's \"floor\"")
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise bad(f"controller: {k} must be a number, got {v!r}")
    steps = data["steps"]
    if not isinstance(steps, list) or not steps:
        raise bad("steps must be a non-empty list")
    intents = []
    for i, st in enumerate(steps):
        intents.extend(_expand(st, i, rate, bad))
        if len(intents) > MAX_STEPS:
            raise bad(f"longer than {MAX_STEPS} steps ({MAX_STEPS / rate:g} s at rate {rate:g})")
    return Script(intents=intents, clip=clip, rate=rate, loop=loop, radius=radius, start=start,
                  drop=drop, floor=floor, controller=dict(ctrl), source=source)


def _controller_keywords():
    import inspect

    sig = inspect.signature(CharacterController.__init__)
    return [p for p in sig.parameters if p not in ("self", "collider", "radius", "position")]


def _expand(st, i, rate, bad):
    where = f"steps[{i}]"
    if not isinstance(st, dict) or not st:
        raise bad(f"{where}: expected an object such as {{\"wait\": 1.0}}, got {st!r}")
    unknown = [k for k in st if k not in ACTIONS]
    if unknown:
        raise bad(f"{where}: unknown key {unknown[0]!r} (expected {', '.join(ACTIONS)})")
    kinds = [k for k in ("wait", "jump", "grab") if k in st]
    if len(kinds) > 1:
        raise bad(f"{where}: one of wait, jump, grab per step, got {' and '.join(kinds)}")
    move = _vector(st["walk"], f"{where}: walk", bad) if "walk" in st else (0.0, 0.0, 0.0)

    def steps_for(key):
        s = _number(st[key], f"{where}: {key}", bad, low=0.0, high=MAX_STEPS / rate)
        return max(1, int(round(s * rate)))

    if "wait" in st:
        if len(st) > 1:
            raise bad(f"{where}: wait takes nothing else, got {', '.join(k for k in st if k != 'wait')}")
        return [Intent()] * steps_for("wait")
    if "jump" in st:
        if st["jump"] is not True:
            raise bad(f"{where}: jump must be true, got {st['jump']!r}")
        if "for" in st:
            raise bad(f"{where}: a jump is one step; it takes no \"for\"")
        return [Intent(move=move, jump=True)]
    if "grab" in st:
        if "for" in st:
            raise bad(f"{where}: grab gives its own duration ({{\"grab\": 2.0}}); no \"for\"")
        return [Intent(move=move, grab=True)] * steps_for("grab")
    if "for" not in st:
        raise bad(f"{where}: walk needs a duration, e.g. {{\"walk\": [1, 0, 0], \"for\": 2.0}}")
    return [Intent(move=move)] * steps_for("for")


def _number(v, name, bad, low=-math.inf, high=math.inf):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise bad(f"{name} must be a number, got {v!r}")
    if not low <= v <= high:
        raise bad(f"{name} must be between {low:g} and {high:g}, got {v!r}")
    return float(v)


def _vector(v, name, bad, unit=True):
    if (not isinstance(v, list) or len(v) != 3
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) for x in v)):
        raise bad(f"{name} must be [x, y, z] (3 numbers), got {v!r}")
    if unit and math.sqrt(sum(x * x for x in v)) > 1.0 + 1e-9:
        raise bad(f"{name} must have length <= 1 (the fraction of the speed), got {v!r}")
    return [float(x) for x in v]


# -- running -----------------------------------------------------------------------------------


def default_script(col: Collider, clip: str, substeps: int = 4, drop: float = 0.15) -> Script:
    """The plain ``colossus play``: dropped above the top of the model, waiting through the clip
    once at ``substeps`` steps per frame."""
    times = col.frame_times(clip)
    rate = col.data.time_codes_per_second * substeps
    n = max(1, int(round((times[-1] - times[0]) / col.data.time_codes_per_second * rate)))
    return Script(intents=[Intent()] * n, clip=clip, rate=rate, loop=False, start="top", drop=drop,
                  source="<default>")


def start_position(col: Collider, clip: str | None, radius: float, drop: float) -> np.ndarray:
    """(3,) above the most upward-facing spot near the middle of the model on the clip's first
    frame, ``radius + drop`` above the surface."""
    t0 = col.frame_times(clip)[0] if clip is not None else 0.0
    pose = col.pose(clip, t0)
    up = col.up
    pts = pose.points.astype(np.float64)
    lo, hi = pts.min(0), pts.max(0)
    axes = [i for i in range(3) if up[i] == 0]  # a grid of downward rays over the footprint
    g = np.linspace(0.15, 0.85, 15)
    u, v = np.meshgrid(g, g)
    o = np.zeros((u.size, 3))
    o[:, axes[0]] = lo[axes[0]] + u.ravel() * (hi - lo)[axes[0]]
    o[:, axes[1]] = lo[axes[1]] + v.ravel() * (hi - lo)[axes[1]]
    top = float((pts @ up).max())
    o += up * (top + 1.0)
    hits = pose.raycast(o, np.repeat(-up[None], len(o), 0))
    ok = hits.hit
    if not ok.any():
        return pts.mean(0) + up * (top - pts.mean(0) @ up + drop + radius)
    n = np.abs(hits.normal[ok] @ up)
    centre = (lo + hi) / 2
    off = np.linalg.norm((hits.point[ok] - centre) - np.outer(hits.point[ok] @ up - centre @ up, up), axis=1)
    score = n - 0.5 * off / max(np.linalg.norm(hi - lo), 1e-12)
    best = hits.point[ok][np.argmax(score)]
    return best + up * (radius + drop)


def lowest_point(col: Collider, clip: str) -> float:
    """The lowest height (along up) the clip's skinned points reach over its frames."""
    up = col.up
    pose = None
    low = math.inf
    for t in col.frame_times(clip):
        pose = col.pose(clip, t, out=pose)
        low = min(low, float((pose.points @ up.astype(np.float32)).min()))
    return low


def run_script(col: Collider, script: Script, clip: str | None = None,
               radius_fraction: float = 0.035) -> Run:
    """Play ``script`` on ``clip`` (default: the script's, else the first) and record every step.

    ``radius_fraction`` is used when the script gives no radius.  Raises :class:`ScriptError`
    when the script does not fit the collider (an unknown clip, controller parameters out of
    range)."""
    clip = clip or script.clip or (col.clips[0] if col.clips else None)
    if clip not in col.clips:
        raise ScriptError(f"{script.source}: no clip {clip!r}; clips: {', '.join(col.clips) or 'none'}")
    times = col.frame_times(clip)
    tcps = col.data.time_codes_per_second
    size = col.size()
    r = (script.radius if script.radius is not None else radius_fraction) * size
    if script.start == "top":
        drop = 0.15 if script.drop is None else script.drop
        start = start_position(col, clip, r, drop * size)
    else:
        start = np.asarray(script.start, dtype=np.float64) + col.up * (script.drop or 0.0) * size
    floor = script.floor
    if floor == "auto":
        floor = lowest_point(col, clip)
    try:
        ctrl = CharacterController(col, r, position=start, floor=floor, **script.controller)
    except (TypeError, ValueError) as e:
        raise ScriptError(f"{script.source}: controller: {one_line(e)}") from None
    t0, t1 = float(times[0]), float(times[-1])
    period = t1 - t0

    def clip_time(k):
        t = t0 + k / script.rate * tcps
        if script.loop and period > 0:
            t = t0 + math.fmod(t - t0, period)
        return t

    dt = 1.0 / script.rate
    n = len(script.intents)
    rec = dict(times=np.empty(n), seconds=np.empty(n), states=np.empty(n, dtype=object),
               positions=np.empty((n, 3)), triangles=np.empty(n, dtype=np.int64),
               penetration=np.empty(n), slip=np.empty(n), energy=np.empty(n),
               on_floor=np.empty(n, dtype=bool), pushed=np.empty(n, dtype=bool))
    a = col.pose(clip, clip_time(0))
    b = col.pose(clip, clip_time(0))
    for k, intent in enumerate(script.intents):
        b = col.pose(clip, clip_time(k + 1), out=b)
        s = ctrl.step(a, b, dt, intent)
        rec["times"][k] = s.time
        rec["seconds"][k] = (k + 1) * dt
        rec["states"][k] = s.state
        rec["positions"][k] = s.position
        rec["triangles"][k] = s.triangle
        rec["penetration"][k] = s.penetration
        rec["slip"][k] = s.slip
        rec["energy"][k] = s.energy
        rec["on_floor"][k] = s.on_floor
        rec["pushed"][k] = s.pushed
        a, b = b, a
    rec["states"] = rec["states"].astype(str)
    return Run(clip=clip, radius=r, rate=script.rate, floor=floor, **rec)


CSV_COLUMNS = ("step", "seconds", "time_code", "state", "x", "y", "z", "triangle", "penetration",
               "slip", "energy", "on_floor")


def write_csv(run: Run, path) -> int:
    """Write one row per step (:data:`CSV_COLUMNS`); returns the number of rows."""
    with open(os.fspath(path), "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        for k in range(len(run.times)):
            x, y, z = run.positions[k]
            w.writerow([k + 1, f"{run.seconds[k]:.6g}", f"{run.times[k]:.6g}", run.states[k],
                        f"{x:.9g}", f"{y:.9g}", f"{z:.9g}", int(run.triangles[k]),
                        f"{run.penetration[k]:.6g}", f"{run.slip[k]:.6g}", f"{run.energy[k]:.4g}",
                        int(run.on_floor[k])])
    return len(run.times)
