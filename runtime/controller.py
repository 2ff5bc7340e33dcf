"""A character controller on a living collider: the seed's player (thesis 4.5 and 5.5).

A sphere of ``radius`` stands, slides, holds (climbs), hangs and falls on a deforming triangle
mesh.  It uses only the public collider API: :meth:`Pose.sphere_contacts`,
:meth:`Pose.raycast`, surface points (:class:`SurfacePoints`, :meth:`Pose.track`) and the
per-step frame of its contacts (:meth:`Pose.surface_frame`).  None of them skins more than the
parts they reach, so a game that only moves players never pays for the whole skin.  The
anchors are game engines' kinematic character controllers - Jolt's
``CharacterVirtual`` (max slope, stick to floor, ground velocity), Godot's
``CharacterBody3D.move_and_slide`` (floor max angle, platform velocity, floor snap), Unity's
``CharacterController`` (slope limit, skin width), PhysX's CCT - none of which works on a
deforming mesh.

>>> ctrl = CharacterController(col, radius=0.1, position=start)
>>> a, b = col.pose("walk", 0.0), col.pose("walk", 0.0)
>>> for k in range(1, 120):                          # 60 steps per second
...     b = col.pose("walk", k * 24 / 60, out=b)
...     s = ctrl.step(a, b, 1 / 60, Intent(move=(1, 0, 0)))
...     a, b = b, a
>>> s.state, s.position, s.penetration

One :meth:`CharacterController.step` from ``pose_prev`` to ``pose_next`` (``dt`` seconds):

1. **Carry** (thesis 5.5.3, "the skin stretches, the player follows").  The contacts of the
   previous step are kept as surface points (triangle + barycentric coordinates).  Their
   centroid and the mean normal of their triangles, on ``pose_prev`` and on ``pose_next``, give
   the surface's local motion: the player moves with the centroid, and its offset from it turns
   with the normal, so it keeps its place on the skin as the skin moves, stretches and turns.
   The centroid's velocity is the *surface velocity*: the held point's speed, and the velocity
   a jump or a fall inherits (momentum inheritance).
2. **Intent and gravity**, by state (below).
3. **Sweep** (thesis 4.3.5, the bullet-through-paper problem).  The player's own displacement
   is cut into sub-steps no longer than ``substep`` (shorter than the radius less the
   tolerance) and the contacts are resolved at each one.  This cannot tunnel: every sub-step
   starts resolved (no deeper than ``tolerance`` into anything, or back where it was), so every
   triangle is at least ``radius - tolerance`` from its start S; a crossing at X within the
   sub-step would need ``|S - X| <= substep < radius - tolerance``.  So the centre never
   crosses a triangle: it meets one as a contact, on the side it came from, and is pushed back
   out on that side.
4. **Resolve** (thesis 5.5.2, discrete collision resolution).  Contacts deeper than
   ``tolerance`` are resolved by moving along the depth-weighted average of their normals, by
   the least distance that clears every contact facing that way (``depth_i / (n_i . n)``, to
   first order: a flat floor clears in one push, a crease in one along its bisector), capped at
   the radius; the contacts are queried again after each push, at most ``max_iterations`` times.
   A position that cannot be cleared (a sphere wedged between two surfaces, thesis figure 16)
   falls back to the sub-step's start.  The part of the remaining motion (and of a falling
   velocity) that points into the surface is removed: the player slides along it.
5. **Classify** from the final contacts, queried with the radius plus ``skin``:

   * ``standing``: contacts (or, when none, a downward ray reaching ``snap`` past touching:
     stick to the floor) find ground whose normal is within ``max_slope`` of up.  Walks at
     ``walk_speed`` along the ground's tangent plane, jumps with ``jump_speed`` on top of the
     surface velocity, refills energy at ``energy_refill`` per second.
   * ``sliding``: touching upward-facing ground steeper than ``max_slope``: slides down it
     under the tangential part of gravity (carried by the surface meanwhile).
   * ``holding``: ``grab`` while touching the collider (and energy left): carried by the held
     points, moves at ``climb_speed`` along the surface's tangent plane in any direction
     (climbing); a ray along the held surface's normal keeps it on a surface that curves away.
   * ``hanging``: holding, but the held point moves faster than ``hold_speed``: cannot move,
     energy drains at ``hang_drain`` per second, and the hold is released when it reaches zero
     (full energy lasts :attr:`CharacterController.hang_time` = ``1 / hang_drain`` seconds of
     hanging).  Energy only refills while standing, so an exhausted player cannot grab again
     before it has stood.
   * ``falling``: none of the above; gravity, up to ``max_fall_speed``.  It lands (standing or
     sliding) on a surface it moves towards, relative to that surface's own velocity, or
     catches hold when ``grab`` is held.

   An optional static terrain plane at height ``floor`` (along the stage's up axis) is ground
   too; it does not move, so nothing standing on it is carried.

Parameters and their defaults (stage units and seconds; the speeds and gravity are SI values
converted with the stage's ``metersPerUnit``, so on the importer's default 1 m/unit stage they
are the numbers shown; lengths tied to the player's size are fractions of the radius):

==================  =================================  ==============================================
parameter           default                            meaning
==================  =================================  ==============================================
``radius``          (required)                         the player sphere, stage units
``walk_speed``      1.5 m/s                            standing: speed along the ground
``climb_speed``     0.5 m/s                            holding: speed along the surface
``jump_speed``      4.0 m/s                            take-off speed along up, added to the surface's
``gravity``         9.81 m/s^2                         along -up
``max_fall_speed``  50 m/s                             terminal speed (falling and sliding)
``hold_speed``      1.5 m/s                            held point speed above which holding is hanging
``max_slope``       45 degrees                         steepest ground that can be stood on
``hang_drain``      0.4 per second                     energy (0..1) lost per second of hanging
``energy_refill``   0.5 per second                     energy regained per second of standing
``skin``            0.05 x radius                      contact margin: touching within radius + skin
``snap``            0.5 x radius                       stick-to-surface reach beyond touching
``substep``         0.5 x radius                       longest sweep sub-step (< radius - tolerance)
``tolerance``       0.002 x radius                     penetration left unresolved
``max_iterations``  4                                  resolution queries per sub-step
``floor``           None                               height of a static terrain plane (None: none)
``sweep_body``      True                               sweep the body's own motion (below); False is
                                                       the thesis' step (the body static within it)
==================  =================================  ==============================================

**The body's own motion is swept too** (issue 25; ``sweep_body``, default on).  Between the
carry and the intent, :func:`runtime.sweep.sweep_sphere` asks whether the body, moving from
``pose_prev`` to ``pose_next`` (a clip between its two times, or the joint-space interpolation of
two arbitrary poses: :class:`runtime.sweep.BodyMotion`), meets the player on its way from where it
was to where the carry put it (what it touched at the end of the last step and its anchors are
carried, not swept: they are left out, of the query and of the resolution below; the query's radius is the
player's less twice ``tolerance``, so resting contacts are not hits).  The query is conservative,
culled per part by a certified bound of how far the body strays from its chord.  When it reports a
contact, the body is stepped from the contact's time to ``pose_next`` in sub-steps that move no
triangle near the player by more than ``substep`` relative to it (the same argument as the sweep
below, with the roles swapped: each sub-step starts resolved, so the body cannot jump over the
centre) and the player is resolved at each sub-pose: pushed out along the surface it met, on the
side it was on, so it stays outside a closed shell.  A pushed airborne player inherits the
surface's velocity along the contact normal (the part of its velocity into the moving surface is
removed); the step's :attr:`Step.pushed` says a push happened.

Limits, stated: the sub-step count bounds the motion of the triangles that can come within
``radius + skin`` plus two radii of the player's unpushed path (a push that carries it further
within one step is not counted); the triangles it already touched are carried, not swept (one of
them that turns and sweeps through it within the step is resolved at the sub-poses only); a
player wedged between the terrain plane and a face coming straight down cannot be cleared
(thesis figure 16) and stays where the resolution leaves it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .collider import Collider, Pose
from .kernels.contact import _MIN_COS, _along, _carry, _length, _summarize, _tangential
from .results import SurfacePoints
from .sweep import BodyMotion, segment_reach, sweep_sphere

STANDING, SLIDING, HOLDING, HANGING, FALLING = "standing", "sliding", "holding", "hanging", "falling"
#: Every state, in a fixed order (their index is the state's code in arrays).
STATES = (STANDING, SLIDING, HOLDING, HANGING, FALLING)

#: SI defaults, converted to stage units with the stage's metersPerUnit.
WALK_SPEED = 1.5  # m/s
CLIMB_SPEED = 0.5  # m/s
JUMP_SPEED = 4.0  # m/s
GRAVITY = 9.81  # m/s^2
MAX_FALL_SPEED = 50.0  # m/s
HOLD_SPEED = 1.5  # m/s
MAX_SLOPE = 45.0  # degrees
HANG_DRAIN = 0.4  # energy per second
ENERGY_REFILL = 0.5  # energy per second
#: Radius-relative defaults.
SKIN = 0.05
SNAP = 0.5
SUBSTEP = 0.5
TOLERANCE = 0.002
MAX_ITERATIONS = 4
#: Penetration (x radius) still left after the iterations that makes a sub-step fall back to its start.
STUCK = 0.1
#: The contact triangle of the terrain plane, and of no contact at all.
NO_TRIANGLE = -1
_ZERO = np.zeros(3)
_ZERO.flags.writeable = False  # shared "no motion"; never written in place


@dataclass(frozen=True)
class Intent:
    """What the player wants this step.

    move : (3,) float64, stage-space wish direction; its length (clamped to 1) is the fraction
        of the state's speed.  It is surface-relative: projected onto the tangent plane of the
        ground (standing) or of the held surface (holding), keeping its length, so "up" climbs a
        wall and "forward" walks up a slope.
    jump : bool, take off (standing only).
    grab : bool, hold on while touching the collider; releasing it lets go.
    """

    move: np.ndarray = (0.0, 0.0, 0.0)
    jump: bool = False
    grab: bool = False

    def __post_init__(self):
        m = np.asarray(self.move, dtype=np.float64).reshape(-1)
        if m.shape != (3,) or not np.isfinite(m).all():
            raise ValueError(f"move must be 3 finite numbers, got {self.move!r}")
        n = float(np.sqrt(m @ m))
        if n > 1.0:
            m = m / n
        object.__setattr__(self, "move", m)
        object.__setattr__(self, "jump", bool(self.jump))
        object.__setattr__(self, "grab", bool(self.grab))
        object.__setattr__(self, "_moving", bool(m.any()))

    @property
    def moving(self) -> bool:
        """Whether ``move`` is not zero."""
        return self._moving


IDLE = Intent()


@dataclass(slots=True)
class Step:
    """The record of one :meth:`CharacterController.step` (copies; safe to keep).

    time : float, ``pose_next``'s time code; seconds : its time in seconds
    state : str, one of :data:`STATES` at the end of the step
    position : (3,) float64, sphere centre, stage space
    velocity : (3,) float64, world velocity (surface velocity + own motion when on a surface)
    surface_velocity : (3,) float64, velocity of the surface points carried this step (zeros when
        none): what a jump or a release inherits
    held_speed : float, its length (the hold's speed, compared with ``hold_speed``)
    triangle : int, the deepest contact's triangle at the end (-1: none, or the terrain plane)
    penetration : float, the deepest contact's depth at the end (stage units, >= 0)
    slip : float, how far the resolution moved the player along the surface, away from where
        the surface's motion and its own intended motion put it (stage units; 0 when airborne)
    energy : float, 0..1
    on_floor : bool, touching the terrain plane
    substeps, queries : int, sweep sub-steps and sphere contact queries this step
    pushed : bool, the moving body hit the player this step and pushed it (module docstring)
    push_triangle : int, the triangle the body's sweep met first (-1: none)
    """

    time: float
    seconds: float
    state: str
    position: np.ndarray
    velocity: np.ndarray
    surface_velocity: np.ndarray
    held_speed: float
    triangle: int
    penetration: float
    slip: float
    energy: float
    on_floor: bool
    substeps: int
    queries: int
    pushed: bool = False
    push_triangle: int = -1


# -- public wrappers of the kernels ------------------------------------------------------------


def resolve_push(normal, depth, tolerance=0.0, cap=np.inf) -> np.ndarray:
    """(3,) the controller's resolution push for contacts ``normal`` (C, 3) unit and
    penetration ``depth`` (C,) (positive = into the surface): along the penetration-weighted
    mean normal, by the least distance that clears every penetrating contact facing it (to
    first order), at most ``cap``; zeros when the deepest is within ``tolerance``."""
    n = np.ascontiguousarray(np.asarray(normal, dtype=np.float64).reshape(-1, 3))
    d = np.ascontiguousarray(np.asarray(depth, dtype=np.float64).reshape(-1))
    if len(n) != len(d):
        raise ValueError(f"normal has {len(n)} rows, depth {len(d)}")
    if not (np.isfinite(n).all() and np.isfinite(d).all()):
        raise ValueError("normal and depth must be finite")
    out = np.empty(12)
    _summarize(n, d, 0.0, float(tolerance), np.array([0.0, 1.0, 0.0]), 2.0, float(cap),
               np.empty(len(n), dtype=np.bool_), out)
    return out[:3].copy()


def carry_point(position, a0, n0, a1, n1) -> np.ndarray:
    """(3,) ``position`` carried by a surface frame moving from centroid ``a0`` with unit normal
    ``n0`` to ``a1``, ``n1``: translated with the centroid, its offset turned by the least
    rotation taking n0 to n1."""
    v = [np.asarray(x, dtype=np.float64).reshape(3) for x in (position, a0, n0, a1, n1)]
    for name, n in (("n0", v[2]), ("n1", v[4])):
        if abs(float(n @ n) - 1.0) > 1e-6:
            raise ValueError(f"{name} must be a unit vector, got {n}")
    out = np.empty(3)
    _carry(v[0], np.concatenate(v[1:3]), np.concatenate(v[3:5]), 1.0, out, np.empty(3))
    return out


# -- the controller ----------------------------------------------------------------------------


@dataclass(slots=True)
class _Touch:
    """Contacts at one position (radius + skin), the terrain plane included, and their summary."""

    triangle: np.ndarray  # (C,) int64, -1 = the terrain plane
    point: np.ndarray  # (C, 3)
    normal: np.ndarray  # (C, 3)
    barycentric: np.ndarray  # (C, 3)
    ground: np.ndarray  # (C,) bool
    summary: np.ndarray  # (12,) see _summarize
    on_floor: bool

    @property
    def count(self):
        return len(self.triangle)


class CharacterController:
    """A player sphere on a collider; see the module docstring for the step, the states and
    every parameter's default (``None`` means the default).

    Attributes (the live state; :meth:`step` updates them)
    ----------
    position : (3,) float64, stage space; velocity : (3,) float64 world velocity
    state : str, one of :data:`STATES`; energy : float 0..1
    anchors : :class:`SurfacePoints` or None, the contacts carried into the next step
    normal : (3,) float64 unit, the surface normal the player moves along (up when airborne)
    """

    def __init__(self, collider: Collider, radius: float, *, walk_speed=None, climb_speed=None,
                 jump_speed=None, gravity=None, max_fall_speed=None, hold_speed=None,
                 max_slope=MAX_SLOPE, hang_drain=HANG_DRAIN, energy_refill=ENERGY_REFILL,
                 skin=None, snap=None, substep=None, tolerance=None, max_iterations=MAX_ITERATIONS,
                 floor=None, position=None, sweep_body=True):
        if not isinstance(collider, Collider):
            raise TypeError(f"collider must be a runtime Collider, got {type(collider).__name__}")
        self.collider = collider
        r = _positive("radius", radius)
        self.radius = r
        si = 1.0 / float(collider.data.meters_per_unit)  # metres -> stage units

        def speed(name, value, default):
            return _nonneg(name, default * si if value is None else value)

        self.walk_speed = speed("walk_speed", walk_speed, WALK_SPEED)
        self.climb_speed = speed("climb_speed", climb_speed, CLIMB_SPEED)
        self.jump_speed = speed("jump_speed", jump_speed, JUMP_SPEED)
        self.gravity = speed("gravity", gravity, GRAVITY)
        self.max_fall_speed = _positive("max_fall_speed", MAX_FALL_SPEED * si if max_fall_speed is None else max_fall_speed)
        self.hold_speed = speed("hold_speed", hold_speed, HOLD_SPEED)
        self.max_slope = _finite("max_slope", max_slope)
        if not 0.0 < self.max_slope < 90.0:
            raise ValueError(f"max_slope must be between 0 and 90 degrees, got {max_slope!r}")
        self.hang_drain = _positive("hang_drain", hang_drain)
        self.energy_refill = _nonneg("energy_refill", energy_refill)
        self.skin = _positive("skin", SKIN * r if skin is None else skin)
        self.snap = _nonneg("snap", SNAP * r if snap is None else snap)
        self.tolerance = _positive("tolerance", TOLERANCE * r if tolerance is None else tolerance)
        if self.tolerance >= self.skin:
            raise ValueError(f"tolerance ({self.tolerance:g}) must be below skin ({self.skin:g})")
        self.substep = _positive("substep", SUBSTEP * r if substep is None else substep)
        if not self.substep < r - self.tolerance:
            raise ValueError(f"substep must be shorter than the radius less the tolerance ({r - self.tolerance:g}) "
                             f"or the sweep can tunnel, got {substep!r}")
        if int(max_iterations) != max_iterations or max_iterations < 1:
            raise ValueError(f"max_iterations must be a whole number >= 1, got {max_iterations!r}")
        self.max_iterations = int(max_iterations)
        self.floor = None if floor is None else _finite("floor", floor)
        self.up = np.ascontiguousarray(collider.up, dtype=np.float64)
        self._g = -self.up * self.gravity
        self._cos_slope = math.cos(math.radians(self.max_slope))
        self._feel = r + self.skin
        self.sweep_body = bool(sweep_body)
        self._scratch = None
        self.place(np.zeros(3) if position is None else position)

    # -- public

    @property
    def hang_time(self) -> float:
        """Seconds of hanging that empty a full energy bar: ``1 / hang_drain``."""
        return 1.0 / self.hang_drain

    def place(self, position, velocity=None, state=FALLING):
        """Put the player at ``position`` (3,) with world ``velocity`` (zeros), airborne (the next
        step lands it if it touches ground); ``state`` may only be ``falling``."""
        if state != FALLING:
            raise ValueError("a placed player starts falling; the next step classifies it")
        self.position = _vec3("position", position)
        self.velocity = np.zeros(3) if velocity is None else _vec3("velocity", velocity)
        self.state = FALLING
        self.energy = 1.0
        self.normal = self.up.copy()
        self._v_rel = _ZERO
        self._resting = None  # the body triangles it touched at the end of the last step
        self._unanchor()

    @property
    def anchors(self) -> SurfacePoints | None:
        """The contacts carried into the next step, as surface points (None: none)."""
        a = self._anchors
        return None if a is None else SurfacePoints(a.triangles.copy(), a.barycentric.copy())

    def step(self, pose_prev: Pose, pose_next: Pose, dt: float, intent: Intent | None = None) -> Step:
        """Advance the player from ``pose_prev`` to ``pose_next`` over ``dt`` seconds (> 0) with
        ``intent`` (:data:`IDLE` when None).  The poses may be the same object or at the same
        time (a still body); they must be poses of this controller's collider.  Returns the
        :class:`Step` record."""
        dt = float(dt)
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        if pose_prev.collider is not self.collider or pose_next.collider is not self.collider:
            raise ValueError("the poses belong to another collider")
        it = IDLE if intent is None else intent
        if not isinstance(it, Intent):
            raise TypeError(f"intent must be an Intent, got {type(it).__name__}")
        self._queries = 0
        pos = self.position
        state = self.state
        anchored = self._anchors is not None
        # 1. carry along the previous contacts
        if anchored:
            pos = np.empty(3)
            v_surf = np.empty(3)
            held_speed = _carry(self.position, self._frame_on(pose_prev), self._frame_on(pose_next), dt,
                                pos, v_surf)
        else:
            v_surf, held_speed = _ZERO, 0.0
        carried = pos
        # 1b. the body's own motion, swept (module docstring)
        push_tri = NO_TRIANGLE
        if self.sweep_body and _moves(pose_prev, pose_next):
            pos, push_tri = self._body_sweep(pose_prev, pose_next, dt, state, pos)
        # 2. intent: transitions it causes, then the state's own motion
        if state in (HOLDING, HANGING) and not it.grab:
            state = self._release(v_surf + self._v_rel)
        elif state in (STANDING, SLIDING) and it.grab and self.energy > 0 and anchored:
            state = HOLDING
        elif state == STANDING and it.jump:
            self.velocity = v_surf + self._along(it, self.walk_speed) + self.jump_speed * self.up
            state = self._release(self.velocity)
        if state == STANDING:
            self._v_rel = self._along(it, self.walk_speed)
        elif state == SLIDING:
            v = self._v_rel + self._g * dt
            v = v - (v @ self.normal) * self.normal
            self._v_rel = _clamp(v, self.max_fall_speed)
        elif state == HOLDING:
            self._v_rel = self._along(it, self.climb_speed)
        elif state == HANGING:
            self._v_rel = _ZERO
        if state == FALLING:
            self.velocity = _clamp(self.velocity + self._g * dt, self.max_fall_speed)
            disp = self.velocity * dt
        else:
            disp = self._v_rel * dt if self._v_rel is not _ZERO else _ZERO
        # 3-4. sweep in sub-steps, resolving each
        pos, touch, substeps = self._sweep(pose_next, pos, disp, state)
        # 5. classify
        pos, touch, state = self._classify(pose_prev, pose_next, dt, state, it, pos, touch, v_surf,
                                           held_speed)
        # energy
        if state == STANDING:
            self.energy = min(1.0, self.energy + self.energy_refill * dt)
        elif state == HANGING:
            self.energy = max(0.0, self.energy - self.hang_drain * dt)
            if self.energy <= 0.0:
                state = self._release(v_surf)
        self.state = state
        self.position = pos
        self._resting = touch.triangle[touch.triangle >= 0]
        if state == FALLING:
            slip, velocity = 0.0, self.velocity.copy()
        else:
            slip = _tangential(pos, carried, disp, self.normal) if anchored else 0.0
            velocity = v_surf + self._v_rel
            self.velocity = velocity.copy()
        deep = int(touch.summary[4])
        return Step(time=float(pose_next.time), seconds=float(pose_next.seconds), state=state,
                    position=pos.copy(), velocity=velocity,
                    surface_velocity=v_surf.copy() if anchored else np.zeros(3),
                    held_speed=held_speed,
                    triangle=int(touch.triangle[deep]) if deep >= 0 else NO_TRIANGLE,
                    penetration=max(0.0, float(touch.summary[3])), slip=slip, energy=self.energy,
                    on_floor=touch.on_floor, substeps=substeps, queries=self._queries,
                    pushed=push_tri != NO_TRIANGLE, push_triangle=push_tri)

    # -- the step's parts

    def _body_sweep(self, pose_prev, pose_next, dt, state, end):
        """Sweep the body's motion against the player moving from :attr:`position` to ``end``:
        (position at ``pose_next``, the triangle first met or -1 when the body did not push it)."""
        start = self.position
        # what it rests on or holds at the start is carried, not swept: its anchors and contacts
        resting = self._resting
        if resting is None:
            t0 = self._touch(pose_prev, start).triangle
            resting = t0[t0 >= 0]
        ignore = resting if self._anchors is None else np.concatenate([resting, self._anchors.triangles])
        skip = None
        if len(ignore):
            skip = np.zeros(len(self.collider.triangles), dtype=np.bool_)
            skip[ignore] = True
        else:
            ignore = None
        motion = BodyMotion(pose_prev, pose_next)
        hit = sweep_sphere(pose_prev, pose_next, start, end, self.radius - 2.0 * self.tolerance, ignore=ignore,
                           motion=motion)
        self._queries += 1
        if hit is None:
            return end, NO_TRIANGLE
        fr = motion.fractions
        push = np.zeros(3)
        last = motion.segments - 1
        # triangles a push of up to a radius could bring near are counted in the sub-step count
        reach_r = self._feel + 2.0 * self.radius
        for i in range(hit.segment, motion.segments):
            f0 = hit.time if i == hit.segment else fr[i]
            f1 = fr[i + 1]
            span = f1 - fr[i]
            if span <= 0:
                continue
            reach = segment_reach(motion, i, start, end, reach_r)
            n = max(1, math.ceil(reach * (f1 - f0) / span / self.substep - 1e-9))
            for j in range(1, n + 1):
                f = f0 + (f1 - f0) * j / n
                if j == n:
                    pose = pose_next if i == last else motion.poses[i + 1]
                else:
                    if self._scratch is None:
                        self._scratch = motion.pose_at(f)
                    pose = motion.pose_at(f, out=self._scratch)
                target = start + f * (end - start) + push
                touch = self._touch(pose, target, skip)
                if touch.summary[3] > self.tolerance:
                    new, touch = self._settle(pose, target, touch, skip)
                    push += new - target
        if not float(push @ push) > self.tolerance * self.tolerance:
            return end + push, NO_TRIANGLE
        if state == FALLING:  # inherit the surface's velocity along the contact normal
            n = hit.normal if float(hit.normal @ (hit.centre - hit.point)) >= 0 else -hit.normal
            k = float((self.velocity - hit.velocity / dt) @ n)
            if k < 0:
                self.velocity = self.velocity - k * n
        return end + push, hit.triangle

    def _along(self, it, speed):
        if not (it.moving and speed > 0):
            return _ZERO
        out = np.empty(3)
        _along(it.move, self.normal, speed, out)
        return out

    def _release(self, velocity):
        """Let go of the surface: airborne with world ``velocity``."""
        self.velocity = np.array(velocity, dtype=np.float64)
        self._unanchor()
        self._v_rel = _ZERO
        self.normal = self.up.copy()
        return FALLING

    def _touch(self, pose, pos, skip=None) -> _Touch:
        """Contacts within radius + skin of ``pos``, the terrain plane included (less the
        triangles ``skip`` (F,) bool marks, when given)."""
        cs = pose.sphere_contacts(pos, self._feel)
        self._queries += 1
        tri, pt, nrm, dep, bar = cs.triangle, cs.point, cs.normal, cs.depth, cs.barycentric
        if skip is not None and len(tri):
            keep = ~skip[tri]
            tri, pt, nrm, dep, bar = tri[keep], pt[keep], nrm[keep], dep[keep], bar[keep]
        on_floor = False
        if self.floor is not None:
            h = float(pos @ self.up) - self.floor
            if h < self._feel:  # a half-space: below it is inside it
                on_floor = True
                tri = np.append(tri, NO_TRIANGLE)
                pt = np.vstack([pt, pos - h * self.up])
                nrm = np.vstack([nrm, self.up])
                dep = np.append(dep, self._feel - h)
                bar = np.vstack([bar, [1.0, 0.0, 0.0]])
        ground = np.empty(len(tri), dtype=np.bool_)
        out = np.empty(12)
        _summarize(nrm, dep, self.skin, self.tolerance, self.up, self._cos_slope, self.radius, ground, out)
        return _Touch(tri, pt, nrm, bar, ground, out, on_floor)

    def _settle(self, pose, pos, touch, skip=None):
        """Resolve ``touch`` at ``pos``: at most ``max_iterations`` pushes, re-querying after each."""
        for _ in range(self.max_iterations):
            if not touch.summary[3] > self.tolerance:
                break
            push = touch.summary[:3]
            if not push.any():  # opposed contacts: nothing clears them (thesis figure 16)
                break
            pos = pos + push
            touch = self._touch(pose, pos, skip)
        return pos, touch

    def _sweep(self, pose, pos, disp, state):
        """Move by ``disp`` in sub-steps of at most ``substep``, resolving each (module docstring)."""
        length = 0.0 if disp is _ZERO else _length(disp)
        n = 1 if length <= self.substep else math.ceil(length / self.substep - 1e-9)
        d = disp / n if n > 1 else disp
        prev = None
        stuck = STUCK * self.radius
        for _ in range(n):
            target = pos + d if length > 0 else pos
            touch = self._touch(pose, target)
            if not touch.summary[3] > self.tolerance:  # clear: the common case
                pos, prev = target, touch
                continue
            new, touch = self._settle(pose, target, touch)
            if touch.summary[3] > stuck:  # cannot be cleared: stay where it was (clear, or carried there)
                new, touch = pos, (prev if prev is not None else self._touch(pose, pos))
            moved = new - target
            mm = float(moved @ moved)
            if mm > 0.0:  # pushed: keep only the motion along the surface
                nh = moved / math.sqrt(mm)
                k = float(d @ nh)
                if k < 0:
                    d = d - k * nh
                if state == FALLING:
                    k = float(self.velocity @ nh)
                    if k < 0:
                        self.velocity = self.velocity - k * nh
                elif state == SLIDING:
                    k = float(self._v_rel @ nh)
                    if k < 0:
                        self._v_rel = self._v_rel - k * nh
            pos, prev = new, touch
        return pos, touch, n

    def _snap(self, pose, pos, direction, reach, ground):
        """Stick to a surface within ``reach`` along unit ``direction`` (stick to floor, floor
        snap): (pos, touch) moved to touch it and resolved, or None when nothing is hit, the hit
        face is not ``ground`` (when asked for), or the moved sphere cannot be cleared.  The
        terrain plane counts when the ray goes down."""
        hit = pose.raycast(pos, direction, reach)
        dist = float(hit.distance[0])
        n = hit.normal[0]
        if self.floor is not None:
            down = -float(direction @ self.up)
            if down > 0:
                h = (float(pos @ self.up) - self.floor) / down
                if 0 <= h < dist and h <= reach:
                    dist, n = h, self.up
        if not math.isfinite(dist):
            return None
        if float(n @ direction) > 0:  # the back of a face: its plane faces the other way
            n = -n
        c = -float(n @ direction)
        if c < _MIN_COS or (ground and float(n @ self.up) < self._cos_slope):
            return None
        move = dist - self.radius / c  # where the sphere touches the hit plane
        new = pos + direction * max(move, 0.0)
        touch = self._touch(pose, new)
        new, touch = self._settle(pose, new, touch)
        if touch.summary[3] > STUCK * self.radius:
            return None
        return new, touch

    def _classify(self, pose_prev, pose_next, dt, state, it, pos, touch, v_surf, held_speed):
        up = self.up
        s = touch.summary
        if state in (HOLDING, HANGING):
            body = touch.triangle >= 0
            if not body.any():
                got = self._snap(pose_next, pos, -self.normal, self.radius + self.snap, False)
                if got is not None:
                    pos, touch = got
                    body = touch.triangle >= 0
            if body.any():
                self._anchor(pose_next, touch, body)
                self.normal = _unit_mean(touch.normal[body], self.normal)
                return pos, touch, HANGING if held_speed > self.hold_speed else HOLDING
            return pos, touch, self._release(v_surf + self._v_rel)
        if state in (STANDING, SLIDING):
            if s[11] == 0:  # no ground among the contacts: a ray down finds it (stick to floor)
                got = None
                if state == STANDING:
                    got = self._snap(pose_next, pos, -up, self.radius / self._cos_slope + self.snap, True)
                if got is None and touch.count == 0:  # steep ground curving away: slide on it
                    got = self._snap(pose_next, pos, -self.normal, self.radius + self.snap, False)
                if got is not None:
                    pos, touch = got
            return self._settle_on(pose_next, pos, touch, v_surf + self._v_rel)
        # falling
        if touch.count == 0:
            return pos, touch, FALLING
        body = touch.triangle >= 0
        if it.grab and self.energy > 0 and body.any():
            self._anchor(pose_next, touch, body)
            self.normal = _unit_mean(touch.normal[body], self.normal)
            self._v_rel = _ZERO
            return pos, touch, HOLDING
        # land only on a surface it moves towards (relative to that surface's own motion)
        v_c = self._contact_velocity(pose_prev, touch, dt)
        n = s[5:8]
        if float((self.velocity - v_c) @ n) > self.tolerance / dt:
            return pos, touch, FALLING
        rel = self.velocity - v_c
        self._v_rel = rel - (rel @ n) * n
        return self._settle_on(pose_next, pos, touch, self.velocity, landing=True)

    def _settle_on(self, pose, pos, touch, velocity, landing=False):
        """Standing, sliding or falling from contacts ``touch`` at ``pos`` (already snapped)."""
        s = touch.summary
        if s[11] > 0:  # ground
            if not touch.on_floor:
                # every contact on the body: anchor on the ground ones (all of them, usually)
                self._anchor(pose, touch, None if s[11] == touch.count else touch.ground)
            elif touch.ground[touch.triangle < 0].any():
                self._unanchor()  # the static terrain: nothing to be carried by
            else:
                self._anchor(pose, touch, touch.ground & (touch.triangle >= 0))
            self.normal = s[8:11].copy()
            self._v_rel = _ZERO
            return pos, touch, STANDING
        if touch.count and float(s[5:8] @ self.up) > 0:  # steep, but facing up: slide
            if touch.on_floor:
                self._anchor(pose, touch, touch.triangle >= 0)
            else:
                self._anchor(pose, touch, None)
            self.normal = s[5:8].copy()
            if not landing:
                self._v_rel = self._v_rel - (self._v_rel @ self.normal) * self.normal
            return pos, touch, SLIDING
        return pos, touch, self._release(velocity)

    def _anchor(self, pose, touch, mask):
        """Keep the contacts of ``touch`` (on ``pose``) selected by ``mask`` (None: all) as the
        surface points to carry the player by, with their frame on ``pose``."""
        if mask is None:
            tri, bary = touch.triangle, touch.barycentric
        elif not mask.any():
            self._unanchor()
            return
        else:
            tri, bary = touch.triangle[mask], touch.barycentric[mask]
        self._anchors = SurfacePoints(tri, bary)
        self._frame_key = _pose_key(pose)
        self._frame_val = self._frame_now(pose)

    def _unanchor(self):
        self._anchors = None
        self._frame_key = self._frame_val = None

    def _frame_on(self, pose):
        """(6,) the anchors' centroid and unit mean triangle normal on ``pose`` (cached for the
        pose the anchors were taken on)."""
        key = _pose_key(pose)
        if key is not None and key == self._frame_key:
            return self._frame_val
        return self._frame_now(pose)

    def _frame_now(self, pose):
        return pose.surface_frame(self._anchors)

    def _contact_velocity(self, pose_prev, touch, dt):
        """(3,) mean velocity of the touched surface points from ``pose_prev`` to now (the
        terrain plane is still)."""
        body = touch.triangle >= 0
        if not body.any():
            return np.zeros(3)
        then = pose_prev.track(touch.triangle[body], touch.barycentric[body])
        return (touch.point[body] - then).sum(0) / (dt * len(touch.triangle))


def _moves(a, b):
    """Whether the body can move from pose ``a`` to pose ``b`` (not one pose, not one clip time)."""
    if a is b:
        return False
    if a.clip is not None and a.clip == b.clip and a.time == b.time:
        return False
    return True


def _pose_key(pose):
    return None if pose.clip is None else (pose.clip, pose.time)


def _unit_mean(v, fallback):
    m = v.sum(0)
    n = float(math.sqrt(m @ m))
    return m / n if n > 0 else fallback


def _clamp(v, limit):
    n = float(math.sqrt(v @ v))
    return v * (limit / n) if n > limit else v


def _finite(name, value):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def _positive(name, value):
    v = _finite(name, value)
    if not v > 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return v


def _nonneg(name, value):
    v = _finite(name, value)
    if v < 0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return v


def _vec3(name, value):
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    if v.shape != (3,) or not np.isfinite(v).all():
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return v.copy()
