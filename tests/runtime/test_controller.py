"""The character controller (runtime.controller) on the samples' real colliders.

Every motion is judged against an independent reference: the surface is skinned by plain
usd-core (``UsdSkelReference``) and searched over ALL triangles in numpy (references/naive_queries.py),
never through the runtime's own posing or queries.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from colossus.runtime import load_collider
from colossus.runtime.controller import (FALLING, HANGING, HOLDING, SLIDING, STANDING, CharacterController,
                                Intent, carry_point, resolve_push)
from colossus.runtime.kernels.contact import _along
from colossus.runtime.script import start_position
from references.usd_reference import UsdSkelReference
from references.naive_queries import (closest_point_on_triangles, inside_closed_mesh, naive_along,
                                naive_carry, naive_push, naive_raycast)

RATE = 60.0  # controller steps per second


class Reference:
    """The clip skinned by usd-core, cached per time code, and brute-force geometry on it."""

    def __init__(self, path, col, clip):
        self.usd = UsdSkelReference(path)
        self.usd.use_clip(clip)
        self.tri = col.triangles
        self.cache = {}

    def points(self, t):
        t = float(t)
        if t not in self.cache:
            self.cache[t] = self.usd.points(t)
        return self.cache[t]

    def closest(self, t, p):
        """(triangle, barycentric (3,), distance) of the nearest surface point to ``p``."""
        P = self.points(t)
        T = self.tri
        q, bary = closest_point_on_triangles(np.asarray(p, float), P[T[:, 0]], P[T[:, 1]], P[T[:, 2]])
        d = np.linalg.norm(q - p, axis=1)
        i = int(np.argmin(d))
        return i, bary[i], float(d[i])

    def at(self, t, tri, bary):
        return np.asarray(bary) @ self.points(t)[self.tri[tri]]

    def frame(self, t, tri):
        """(3, 3) rows: an orthonormal frame of the triangle (edge, in-plane, normal)."""
        a, b, c = self.points(t)[self.tri[tri]]
        e1 = (b - a) / np.linalg.norm(b - a)
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n)
        return np.array([e1, np.cross(n, e1), n])


@pytest.fixture(scope="module")
def creature_ref(creature_path, creature):
    return Reference(creature_path, creature, "walk")


@pytest.fixture(scope="module")
def limb_ref(limb_path, limb):
    return Reference(limb_path, limb, "bend")


def clip_time(col, clip, t):
    """``t`` wrapped into the clip (the walk is a cycle: its last frame is its first)."""
    times = col.frame_times(clip)
    return float(times[0] + math.fmod(t - times[0], times[-1] - times[0]))


def play(ctrl, col, clip, t_start, n, intents=None):
    """``n`` controller steps at RATE from clip time ``t_start``; [(t_prev, t_next, Step)]."""
    tc = col.data.time_codes_per_second
    a = col.pose(clip, clip_time(col, clip, t_start))
    b = col.pose(clip, a.time)
    out = []
    for k in range(n):
        tb = clip_time(col, clip, t_start + (k + 1) * tc / RATE)
        b = col.pose(clip, tb, out=b)
        it = intents(k) if callable(intents) else intents
        out.append((a.time, tb, ctrl.step(a, b, 1 / RATE, it)))
        a, b = b, a
    return out


def settle(ctrl, pose, steps=5):
    return [ctrl.step(pose, pose, 1 / RATE) for _ in range(steps)][-1]


# -- the kernels against their numpy references ---------------------------------------------


def test_kernels_match_numpy_references():
    rng = np.random.default_rng(7)
    for _ in range(200):
        C = int(rng.integers(0, 12))
        n = rng.normal(size=(C, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        pen = rng.normal(scale=0.1, size=C)
        tol, cap = float(rng.uniform(0, 0.05)), float(rng.uniform(0.05, 1.0))
        assert np.allclose(resolve_push(n, pen, tol, cap), naive_push(n, pen, tol, cap), atol=1e-12)
        n0, n1 = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 3)))
        if n0 @ n1 > -0.95:
            p, a0, a1 = rng.normal(size=(3, 3))
            assert np.allclose(carry_point(p, a0, n0, a1, n1), naive_carry(p, a0, n0, a1, n1), atol=1e-12)
        move = rng.normal(size=3) * rng.uniform(0, 1)
        out = np.empty(3)
        _along(move, n0, 2.5, out)
        assert np.allclose(out, naive_along(move, n0, 2.5), atol=1e-12)
    with pytest.raises(ValueError, match="unit"):
        carry_point(np.zeros(3), np.zeros(3), [0, 2, 0], np.zeros(3), [0, 1, 0])


# -- standing ---------------------------------------------------------------------------------


def _tail_spot(col, r):
    """Above the up-facing triangle of the creature's middle tail part that moves most over the walk."""
    pose = col.pose("walk", 0.0)
    nrm = pose.face_normals()
    part = col.data.joints.index(next(j for j in col.data.joints if j.endswith("tail_1")))
    cand = np.nonzero((col.data.face_part == part) & (nrm @ col.up > 0.97))[0]
    cen = lambda t: col.pose("walk", t).points[col.triangles[cand]].mean(1).astype(np.float64)  # noqa: E731
    c0 = cen(0.0)
    travel = np.max([np.linalg.norm(cen(t) - c0, axis=1) for t in col.frame_times("walk")], axis=0)
    f = int(np.argmax(travel))
    return c0[f] + nrm[cand[f]] * r


@pytest.mark.parametrize("where", ["back", "tail"])
def test_standing_still_through_the_whole_walk(creature, creature_ref, where):
    """On the back (the issue's case) and on the swinging tail (it travels a few radii and turns):
    the player keeps its place on the skin."""
    col, ref = creature, creature_ref
    r = 0.035 * col.size()
    start = start_position(col, "walk", r, 0.0) if where == "back" else _tail_spot(col, r)
    ctrl = CharacterController(col, r, position=start)
    assert settle(ctrl, col.pose("walk", 0.0)).state == STANDING
    tri, bary, dist = ref.closest(0.0, ctrl.position)
    assert abs(dist - r) < 0.01 * r
    off0 = ref.frame(0.0, tri) @ (ctrl.position - ref.at(0.0, tri, bary))
    times = col.frame_times("walk")
    n = int(round((times[-1] - times[0]) / col.data.time_codes_per_second * RATE))
    drift, depth, travel = [], [], []
    for _, t, s in play(ctrl, col, "walk", 0.0, n):
        assert s.state == STANDING, (t, s.state)
        foot = ref.at(t, tri, bary)
        travel.append(np.linalg.norm(foot - ref.at(0.0, tri, bary)))
        drift.append(np.linalg.norm(ref.frame(t, tri) @ (s.position - foot) - off0))
        depth.append(r - ref.closest(t, s.position)[2])
    seconds = n / RATE
    assert max(travel) > (0.2 if where == "back" else 2.0) * r  # the skin really moves under it
    # relative to the skin point it stands on, after the cycle: under 1 % of the radius per second
    assert drift[-1] < 0.01 * r * seconds, drift[-1] / r
    # ... and on the way (the back: at every moment; the thin tail bends under the sphere)
    assert max(drift) < (0.01 * seconds if where == "back" else 0.05) * r, max(drift) / r
    assert max(depth) < 0.01 * r, max(depth) / r  # penetration (brute force on usd-core points)


def test_steps_skin_only_the_parts_they_reach(creature):
    """A player walking on lazily posed frames never makes the pose skin the whole mesh, and
    moves bit for bit as one on fully skinned frames (the lazy path is the same kernel)."""
    col = creature
    r = 0.035 * col.size()
    start = start_position(col, "walk", r, 0.0)
    runs = []
    for full in (False, True):
        ctrl = CharacterController(col, r, position=start)
        a, b = col.pose("walk", 0.0), col.pose("walk", 0.0)
        rows = []
        for k in range(90):
            b = col.pose("walk", clip_time(col, "walk", (k + 1) * col.data.time_codes_per_second / RATE), out=b)
            if full:
                b.points
            s = ctrl.step(a, b, 1 / RATE, Intent(move=(1, 0, 0), jump=k == 40))
            if not full:
                assert b._full != b._version, k  # private flag: there is no public one
            rows.append((s.state, s.triangle, *s.position, *s.velocity))
            a, b = b, a
        runs.append(rows)
    assert runs[0] == runs[1]
    assert {row[0] for row in runs[0]} >= {STANDING, FALLING}


def _slope_spot(col, pose, r, lo=25.0, hi=40.0):
    """A surface point whose slope is between ``lo`` and ``hi`` degrees and smooth around it
    (the faces within half a radius face within 12 degrees of it): (point, unit normal, slope in
    degrees)."""
    up = col.up
    pts = pose.points.astype(np.float64)
    tri = col.triangles
    cen = pts[tri].mean(1)
    nrm = pose.face_normals()
    ang = np.degrees(np.arccos(np.clip(nrm @ up, -1, 1)))
    # closest to the middle slope first (to 0.01 degree: faces of one plane tie), then by position
    # (not by the mesh's face order, which depends on the reader)
    order = np.lexsort((cen[:, 2], cen[:, 1], cen[:, 0], np.round(np.abs(ang - (lo + hi) / 2), 2)))
    for f in order:
        if not lo <= ang[f] <= hi:
            break
        near = np.linalg.norm(cen - cen[f], axis=1) < 0.5 * r
        if (nrm[near] @ nrm[f]).min() > math.cos(math.radians(12)):
            return cen[f], nrm[f], float(ang[f])
    pytest.fail("no nearly planar slope on the sample")


def test_slides_on_a_slope_steeper_than_max_slope_and_stays_on_a_gentler_one(creature):
    col = creature
    r = 0.035 * col.size()
    pose = col.pose("walk", 0.0)  # one still frame
    point, normal, slope = _slope_spot(col, pose, r)
    start = point + normal * r
    up = col.up
    downhill = -up - (-up @ normal) * normal
    for max_slope, slides in ((slope + 12, False), (slope - 12, True)):
        ctrl = CharacterController(col, r, max_slope=max_slope, position=start)
        steps = [ctrl.step(pose, pose, 1 / RATE) for _ in range(30)]
        moved = steps[-1].position - start
        if slides:
            assert [s.state for s in steps[:5]] == [SLIDING] * 5
            assert (steps[4].position - start) @ downhill > 0  # down the slope, along it
            assert moved @ up < -r
        else:
            assert all(s.state == STANDING for s in steps)
            # landing pushed it out along the normal (a little along the slope); then it stays
            assert np.linalg.norm(steps[0].position - start) < 0.02 * r
            assert np.linalg.norm(steps[-1].position - steps[0].position) < 1e-3 * r


# -- holding, hanging, falling, landing --------------------------------------------------------


def _flank(col, t=0.0):
    """A point on the creature's flank at the middle of its back: ray in from the side."""
    pose = col.pose("walk", t)
    mid = pose.joint_world[col.data.joints.index(next(j for j in col.data.joints if j.endswith("spine_1")))][:3, 3]  # column-vector: translation in the last column
    hit = pose.raycast(mid + [5.0, 0.0, 0.0], [-1.0, 0.0, 0.0])
    assert hit.hit[0] and abs(hit.normal[0] @ col.up) < 0.3
    return hit.point[0], hit.normal[0]


@pytest.mark.parametrize("direction", ["up", "along"])
def test_grab_on_the_flank_and_climb_keeps_contact(creature, creature_ref, direction):
    col, ref = creature, creature_ref
    r = 0.035 * col.size()
    point, normal = _flank(col)
    ctrl = CharacterController(col, r, position=point + normal * r)
    move = col.up if direction == "up" else np.cross(normal, col.up)  # up the flank, or along it
    steps = play(ctrl, col, "walk", 0.0, int(RATE), Intent(move=move, grab=True))
    skin = ctrl.skin
    for _, t, s in steps:
        assert s.state == HOLDING, (t, s.state)
        d = ref.closest(t, s.position)[2]
        assert r - 0.01 * r <= d <= r + skin + 0.01 * r, (t, d / r)  # touching, not in it
    rise = (steps[-1][2].position - steps[0][2].position) @ col.up
    if direction == "up":
        assert rise > 0.5 * ctrl.climb_speed * 1.0  # climbed (0.5 m/s for a second, on a curve)
    else:
        along = (steps[-1][2].position - steps[0][2].position) @ move
        assert along > 0.5 * ctrl.climb_speed


def test_hanging_drains_energy_releases_falls_and_lands_again(creature, creature_ref):
    col, ref = creature, creature_ref
    r = 0.035 * col.size()
    point, normal = _flank(col)
    tri, bary, _ = ref.closest(0.0, point)
    tc = col.data.time_codes_per_second
    hang_time = 1.0 / 0.4  # the default hang_drain: 2.5 s of hanging empty a full bar
    n_grab = int((hang_time + 0.5) * RATE)
    # the flank's own speed at the grab point, from usd-core points, over the whole hold
    ts = [clip_time(col, "walk", k * tc / RATE) for k in range(n_grab + 1)]
    speeds = [np.linalg.norm(ref.at(b, tri, bary) - ref.at(a, tri, bary)) * RATE for a, b in zip(ts, ts[1:])]
    low = float(min(speeds))
    assert low > 0
    floor = min(float(ref.points(t)[:, 1].min()) for t in col.frame_times("walk"))
    ctrl = CharacterController(col, r, position=point + normal * r, hold_speed=0.5 * low, floor=floor)
    assert ctrl.hang_time == pytest.approx(hang_time)
    steps = [s for _, _, s in play(ctrl, col, "walk", 0.0, n_grab + int(2 * RATE),
                                   lambda k: Intent(grab=k < n_grab))]
    states = [s.state for s in steps]
    assert states[0] == HOLDING and states[1] == HANGING  # the first step has no held speed yet
    k_fall = states.index(FALLING)
    assert set(states[1:k_fall]) == {HANGING}
    hung = k_fall / RATE  # steps 1 .. k_fall drained (the last one empties the bar and lets go)
    assert abs(hung - hang_time) <= 1 / RATE + 1e-9, hung
    assert steps[k_fall].energy == 0.0 and steps[k_fall - 1].energy > 0.0
    # letting go keeps the flank's velocity
    assert np.linalg.norm(steps[k_fall].surface_velocity) > 0.5 * low
    assert np.array_equal(steps[k_fall].velocity, steps[k_fall].surface_velocity)
    k_land = next(k for k in range(k_fall, len(steps)) if steps[k].state == STANDING)
    assert steps[k_land].on_floor
    height = steps[k_fall].position @ col.up - (floor + r)
    assert (k_land - k_fall) / RATE < math.sqrt(2 * height / ctrl.gravity) + 0.25
    assert all(s.state == STANDING for s in steps[k_land:])
    assert abs(steps[k_land].position @ col.up - (floor + r)) < 0.01 * r
    # energy refills while standing
    k = min(len(steps) - 1, k_land + int(RATE / 2))
    assert steps[k].energy == pytest.approx((k - k_land + 1) / RATE * ctrl.energy_refill, abs=1e-9)
    with pytest.raises(StopIteration):  # an empty bar cannot grab again before it has stood
        next(s for s in steps[k_fall:k_land] if s.state in (HOLDING, HANGING))


# -- momentum inheritance ---------------------------------------------------------------------


def test_a_jump_off_a_moving_limb_keeps_the_limb_velocity(limb, limb_ref):
    col, ref = limb, limb_ref
    r = 0.035 * col.size()
    t0 = 12.0  # the limb is curled: its upper side faces up, and it rises from here
    pose = col.pose("bend", t0)
    top = pose.points[np.argmax(pose.points[:, 1])].astype(np.float64)
    hit = pose.raycast(top + [0.0, 1.0, 0.0], [0.0, -1.0, 0.0])
    ctrl = CharacterController(col, r, position=hit.point[0] + hit.normal[0] * r)
    assert settle(ctrl, pose).state == STANDING
    ride = play(ctrl, col, "bend", t0, 10)
    assert all(s.state == STANDING for _, _, s in ride)
    anchors = ctrl.anchors
    t_prev = ride[-1][1]
    (ta, tb, jump), = play(ctrl, col, "bend", t_prev, 1, Intent(jump=True))
    # the velocity of the stood-on skin points over that step, from usd-core points
    v_limb = np.mean([ref.at(tb, f, b) - ref.at(ta, f, b) for f, b in zip(anchors.triangles, anchors.barycentric)],
                     axis=0) * RATE
    up = col.up
    assert np.linalg.norm(v_limb - (v_limb @ up) * up) > 1.0  # the limb is moving fast sideways
    assert jump.state == FALLING
    expect = v_limb + ctrl.jump_speed * up + ctrl._g / RATE  # take-off, then a step of gravity
    assert np.allclose(jump.velocity, expect, atol=1e-3 * np.linalg.norm(expect))
    # ballistic from there: the horizontal motion is the limb's
    flight = play(ctrl, col, "bend", tb, 8)
    assert all(s.state == FALLING for _, _, s in flight)
    d = flight[-1][2].position - jump.position
    h = v_limb - (v_limb @ up) * up
    assert np.allclose(d - (d @ up) * up, h * 8 / RATE, atol=1e-3 * np.linalg.norm(h * 8 / RATE))


# -- sweeps (no tunnelling) ---------------------------------------------------------------------


def test_a_fast_player_never_passes_through_a_thin_limb(limb, limb_ref):
    """Shots at 30 m/s, one 1/24 s step each (10 radii): brute force over every triangle of the
    usd-core-skinned limb says ours always stops on the near side, while a plain discrete step
    to the end point would have passed through most of the time."""
    col, ref = limb, limb_ref
    r = 0.035 * col.size()
    T = col.triangles
    rng = np.random.default_rng(11)
    dt, speed = 1 / 24, 30.0
    shots = tunnelled_naive = 0
    for t, moving in ((0.0, False), (6.0, False), (12.0, True), (18.0, True)):
        pa, pb = col.pose("bend", t), col.pose("bend", t + (1.0 if moving else 0.0))
        P = ref.points(pb.time)
        N = np.cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]])
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        for _ in range(20):
            f = int(rng.integers(len(T)))
            aim = rng.dirichlet([1, 1, 1]) @ P[T[f]]
            d = -N[f] + rng.normal(scale=0.25, size=3)
            d /= np.linalg.norm(d)
            start = aim - d * (r + 0.3)
            if ref.closest(pb.time, start)[2] < 1.2 * r or inside_closed_mesh(P, T, start):
                continue  # start clear of the limb
            ctrl = CharacterController(col, r, position=start, gravity=0.0, max_fall_speed=100.0)
            ctrl.velocity = d * speed
            s = ctrl.step(pa, pb, dt)
            shots += 1
            # ours: the centre never crossed the surface, ends outside, not inside the limb
            seg = s.position - start
            if np.linalg.norm(seg) > 0:
                assert naive_raycast(P, T, start[None], seg[None], np.linalg.norm(seg))[1][0] == -1
            assert not inside_closed_mesh(P, T, s.position)
            assert ref.closest(pb.time, s.position)[2] > r - 0.01 * r
            assert s.substeps >= 20 and s.queries <= s.substeps * (ctrl.max_iterations + 2) + 2 * (ctrl.max_iterations + 1)
            # a single discrete step: straight to the end, where nothing touches any more
            end = start + d * speed * dt
            crossed = naive_raycast(P, T, start[None], (end - start)[None], speed * dt)[1][0] >= 0
            if crossed and ref.closest(pb.time, end)[2] > r and not inside_closed_mesh(P, T, end):
                tunnelled_naive += 1
    assert shots >= 60
    assert tunnelled_naive > shots / 2  # the shots are ones a discrete step would miss


# -- parameters ---------------------------------------------------------------------------------


def test_parameters_and_intent_are_checked(limb, limb_path):
    r = 0.1
    ok = CharacterController(limb, r)
    assert ok.walk_speed == pytest.approx(1.5 / limb.data.meters_per_unit)
    assert ok.skin == pytest.approx(0.05 * r) and ok.substep == pytest.approx(0.5 * r)
    for kw, msg in [({"substep": r}, "shorter than the radius"), ({"max_slope": 95}, "between 0 and 90"),
                    ({"hang_drain": 0}, "> 0"), ({"walk_speed": -1}, ">= 0"),
                    ({"tolerance": 0.5 * r}, "below skin"), ({"max_iterations": 0}, ">= 1"),
                    ({"floor": float("nan")}, "finite")]:
        with pytest.raises(ValueError, match=msg):
            CharacterController(limb, r, **kw)
    with pytest.raises(ValueError, match="radius"):
        CharacterController(limb, 0.0)
    with pytest.raises(ValueError, match="move"):
        Intent(move=(1, 2))
    assert np.allclose(Intent(move=(3, 0, 4)).move, [0.6, 0, 0.8])  # clamped to length 1
    pose = limb.pose("bend", 0.0)
    with pytest.raises(ValueError, match="dt"):
        ok.step(pose, pose, 0.0)
    with pytest.raises(ValueError, match="another collider"):
        ok.step(pose, load_collider(limb_path).pose("bend", 0.0), 0.1)
    with pytest.raises(TypeError, match="Intent"):
        ok.step(pose, pose, 0.1, {"jump": True})
