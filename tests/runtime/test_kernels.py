"""The one skinning kernel, UsdSkel's interpolation and the sound bounds (runtime.kernels,
runtime.certify), against readable numpy references (tests/references/naive.py) and usd-core."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Usd, UsdSkel, Vt
from scipy.spatial.transform import Rotation

from references import naive
from colossus.runtime import certify as C
from colossus.runtime import certify_dq as CDQ
from colossus.runtime.schema import Clip
from colossus.runtime.kernels import bounds as B
from colossus.runtime.kernels import interval as IV
from colossus.runtime.kernels import pose as PK
from colossus.runtime.kernels import skin as SK


def _random_skin(rng, n=300, J=6, k=4, F=5):
    pts = rng.normal(size=(n, 3)).astype(np.float32)
    ji = rng.integers(0, J, size=(n, k)).astype(np.int32)
    jw = rng.random((n, k)).astype(np.float32)
    jw[:, -1] = 0
    jw /= jw.sum(1, keepdims=True)
    ji[:, -1] = 99  # padding: a zero weight may name any joint
    m = np.repeat(np.eye(4)[None, None], F, 0).repeat(J, 1)
    m[..., :3, :3] += 0.3 * rng.normal(size=(F, J, 3, 3))
    m[..., :3, 3] = rng.normal(size=(F, J, 3))
    return pts, ji, jw, m


# -- skin --------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [50, 9000])  # serial and parallel kernels
def test_skin_frames_matches_naive_lbs(n):
    rng = np.random.default_rng(1)
    pts, ji, jw, m = _random_skin(rng, n=n)
    got = SK.skin_frames(pts, ji, jw, m)
    ref = naive.naive_lbs(pts, ji, jw, m)
    assert got.dtype == np.float32 and got.shape == ref.shape
    np.testing.assert_allclose(got, ref, atol=2e-5)


def test_part_farthest_matches_naive_lbs_and_todo():
    rng = np.random.default_rng(2)
    pts, ji, jw, m = _random_skin(rng)
    poff = np.array([0, 10, 10, 200])
    pv = rng.choice(len(pts), size=200, replace=True).astype(np.int32)
    centers = rng.normal(size=(m.shape[0], 3, 3))
    todo = rng.random((m.shape[0], 3)) < 0.6
    d, v = SK.part_farthest(pts, ji, jw, m, poff, pv, centers, todo=todo)
    sk = naive.naive_lbs(pts, ji, jw, m)
    for f in range(m.shape[0]):
        for p in range(3):
            verts = pv[poff[p]:poff[p + 1]]
            if not todo[f, p]:
                assert np.isnan(d[f, p]) and v[f, p] == -1
            elif len(verts) == 0:
                assert d[f, p] == 0 and v[f, p] == -1
            else:
                dist = np.linalg.norm(sk[f, verts] - centers[f, p], axis=1)
                assert d[f, p] == pytest.approx(dist.max(), abs=1e-9)
                assert v[f, p] in verts[dist == dist.max()]


def _dq_rig(rng, n=300, J=7, k=4, F=6, kind="rigid"):
    """Random DQS inputs: per-frame skinning transforms with large rotations (hemisphere flips),
    and (``kind``) uniform / non-uniform scales, shear, a mirrored joint or a singular one."""
    pts = (2 * rng.normal(size=(n, 3))).astype(np.float32)
    ji = rng.integers(0, J, size=(n, k)).astype(np.int32)
    jw = (rng.random((n, k)) * (rng.random((n, k)) < 0.8)).astype(np.float32)
    jw[:, 0] += 1e-3
    jw = (jw / jw.sum(1, keepdims=True)).astype(np.float32)
    ji[jw == 0] = 99  # padding may name any joint
    m = np.repeat(np.eye(4)[None, None], F, 0).repeat(J, 1)
    m[..., :3, :3] = Rotation.random(F * J, random_state=int(rng.integers(1 << 30))).as_matrix().reshape(F, J, 3, 3)
    if kind in ("uniform", "nonuniform", "shear", "mirror", "singular"):
        s = rng.uniform(0.6, 1.5, size=(F, J, 1 if kind == "uniform" else 3))
        m[..., :3, :3] = m[..., :3, :3] * s[..., None, :]
    if kind == "shear":
        m[..., :3, :3] += 0.2 * rng.normal(size=(F, J, 3, 3))
    if kind == "mirror":
        m[:, 1, :3, :3] *= -1
    if kind == "singular":
        m[:, 2, :3, :3] *= 1e-4  # |det| < 1e-10: UsdSkel's Factor gives up on it
    m[..., :3, 3] = 3 * rng.normal(size=(F, J, 3))
    G = np.eye(4)
    G[:3, :3] = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix() * 1.3
    G[:3, 3] = rng.normal(size=3)
    return pts, ji, jw, m, G


def _usd_dqs(pts, ji, jw, m, G):
    """usd-core's own dual-quaternion skinning of every frame of ``m``: (F, n, 3) float64."""
    out = []
    g = Gf.Matrix4d(*np.asarray(G).T.reshape(-1).tolist())
    idx = Vt.IntArray.FromNumpy(np.where(jw == 0, 0, ji).reshape(-1).astype(np.int32))
    wts = Vt.FloatArray.FromNumpy(jw.reshape(-1))
    for mf in m:
        xf = Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(np.swapaxes(mf, -1, -2)))
        p = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pts))
        assert UsdSkel.SkinPoints(UsdSkel.Tokens.dualQuaternion, g, xf, idx, wts, ji.shape[1], p)
        out.append(np.asarray(p, dtype=np.float64))
    return np.array(out)


@pytest.mark.parametrize("kind", ["rigid", "uniform", "nonuniform", "shear", "mirror", "singular"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dqs_matches_usdskel_on_every_frame(kind, seed):
    """The one kernel's dual-quaternion switch is UsdSkel's DQS, scale and shear included."""
    rng = np.random.default_rng(100 + seed)
    pts, ji, jw, m, G = _dq_rig(rng, kind=kind)
    ref = _usd_dqs(pts, ji, jw, m, G)
    got = SK.skin_frames(pts, ji, jw, SK.fold_dq(m, G), dtype=np.float64)
    size = np.linalg.norm(ref.reshape(-1, 3).max(0) - ref.reshape(-1, 3).min(0))
    assert np.abs(got - ref).max() <= 1e-6 * size
    assert np.abs(SK.skin_frames(pts, ji, jw, SK.fold_method("dualQuaternion", m, G)) - ref).max() <= 1e-6 * size


@pytest.mark.parametrize("n", [50, 9000])  # serial and parallel kernels
@pytest.mark.parametrize("kind", ["rigid", "nonuniform", "mirror"])
def test_dqs_matches_naive_dqs(n, kind):
    rng = np.random.default_rng(7)
    pts, ji, jw, m, G = _dq_rig(rng, n=n, F=2, kind=kind)
    W = np.eye(4)
    W[:3, :3] = 2.0 * Rotation.random(random_state=3).as_matrix()
    W[:3, 3] = [1, 2, 3]
    got = SK.skin_frames(pts, ji, jw, SK.fold_dq(m, G, W), dtype=np.float64)
    ref = naive.naive_dqs(pts, ji, jw, m, G) @ W[:3, :3].T + W[:3, 3] if n < 1000 else None
    if ref is None:  # the parallel driver against the serial one
        ref = SK.skin_frames(pts[:200], ji[:200], jw[:200], SK.fold_dq(m, G, W), dtype=np.float64)
        got = got[:, :200]
    np.testing.assert_allclose(got, ref, atol=1e-9 * np.abs(ref).max())


def test_dqs_part_farthest_and_subset_use_the_switch():
    rng = np.random.default_rng(8)
    pts, ji, jw, m, G = _dq_rig(rng, F=3, kind="uniform")
    mats = SK.fold_dq(m, G)
    ref = naive.naive_dqs(pts, ji, jw, m, G)
    poff = np.array([0, 40, 300])
    pv = np.arange(300, dtype=np.int32)
    c = rng.normal(size=(3, 2, 3))
    d, v = SK.part_farthest(pts, ji, jw, mats, poff, pv, c)
    for f in range(3):
        for p in range(2):
            vs = pv[poff[p]:poff[p + 1]]
            dist = np.linalg.norm(ref[f, vs] - c[f, p], axis=1)
            assert d[f, p] == pytest.approx(dist.max(), rel=1e-9) and v[f, p] == vs[np.argmax(dist)]
    out = np.zeros((300, 3), np.float32)
    pi, pj, pw = SK.check_skin_inputs(pts, ji, jw, m.shape[1])
    SK._skin_subset(pv, 0, 300, pi, pj, pw, np.ascontiguousarray(mats[:1]), out)
    np.testing.assert_allclose(out, ref[0], atol=1e-5 * np.abs(ref).max())


def test_skin_inputs_one_padding_policy():
    rng = np.random.default_rng(3)
    pts, ji, jw, m = _random_skin(rng)
    with pytest.raises(ValueError, match="joint_weights"):
        SK.skin_frames(pts, ji, jw[:, :2], m)
    bad = ji.copy()
    bad[0, 0] = 99  # a non-zero weight on a joint that does not exist
    with pytest.raises(ValueError, match="joint_indices"):
        SK.skin_frames(pts, bad, jw, m)
    nan = pts.copy()
    nan[3] = np.nan
    d, v = SK.part_farthest(nan, ji, jw, m[:1], [0, 10], np.arange(10), np.zeros((1, 1, 3)))
    assert np.isinf(d[0, 0]) and v[0, 0] == 3  # a NaN point reads as infinitely far


# -- pose: UsdSkel's interpolation -----------------------------------------------------------
def _usd_clip(q0, q1, t0=(0, 0, 0), t1=(1, 2, 3), s0=(1, 1, 1), s1=(2, 1, 0.5)):
    stage = Usd.Stage.CreateInMemory()
    anim = UsdSkel.Animation.Define(stage, "/A")
    anim.CreateJointsAttr(["a"])
    for tc, q, t, s in ((0.0, q0, t0, s0), (1.0, q1, t1, s1)):
        anim.CreateRotationsAttr().Set(Vt.QuatfArray([Gf.Quatf(float(q[3]), *map(float, q[:3]))]), tc)
        anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*t)]), tc)
        anim.CreateScalesAttr().Set(Vt.Vec3hArray([Gf.Vec3h(*s)]), tc)
    cache = UsdSkel.Cache()
    return stage, cache, cache.GetAnimQuery(anim)


@pytest.mark.parametrize("compiled", [True, False])
def test_interpolation_matches_usdskel_shortest_arc(compiled):
    """GfSlerp takes the shortest arc: with q0 . q1 < 0 it negates q1; the runtime's port does too
    (the compiled kernel and the numpy path the proof takes on small clips)."""
    rng = np.random.default_rng(4)
    for trial in range(6):
        q0 = Rotation.random(random_state=trial).as_quat()
        q1 = Rotation.random(random_state=100 + trial).as_quat()
        if np.dot(q0, q1) > 0:
            q1 = -q1  # force the negative dot product
        if trial == 5:
            q1 = -(q0 + 1e-4 * rng.normal(size=4))  # the nearly parallel (linear) branch
            q1 /= np.linalg.norm(q1)
        stage, cache, query = _usd_clip(q0, q1)
        clip = Clip("A", "/A", np.array([0.0, 1.0]), np.array([[[0, 0, 0]], [[1, 2, 3]]], float),
                        np.array([0.0, 1.0]), np.array([[q0], [q1]]).astype(np.float32).astype(float),
                        np.array([0.0, 1.0]), np.array([[[1, 1, 1]], [[2, 1, 0.5]]], float),
                        np.array([0]), np.array([0.0, 1.0]))
        for a in (0.0, 0.25, 0.5, 0.9):
            ours = PK.locals_at(clip, [a], np.eye(4)[None], compiled=compiled)[0, 0]
            ref = np.array(query.ComputeJointLocalTransforms(Usd.TimeCode(a))[0]).T  # row -> column vector
            np.testing.assert_allclose(ours, ref, atol=2e-6)
            qa = naive.slerp(clip.vr[0, 0], clip.vr[1, 0], a)
            h = np.float16  # UsdSkel lerps half3 scales in half precision
            sa = [float(h(h((1 - a) * s0) + h(a * s1))) for s0, s1 in zip((1, 1, 1), (2, 1, 0.5))]
            want = naive.trs([[a, 2 * a, 3 * a]], qa[None], [sa])[0]
            np.testing.assert_allclose(ours, want, atol=1e-5)


def test_locals_at_numpy_path_equals_the_kernel():
    """The numpy path of ``locals_at`` against the compiled kernel on a clip whose channels have
    their own sample times: times before, after and exactly on samples, a nearly parallel
    rotation pair (GfSlerp's linear branch), opposite hemispheres, half-precision scales."""
    rng = np.random.default_rng(21)
    A, J = 5, 7
    tt, tr, ts = np.array([0.0, 2, 3, 7]), np.array([1.0, 4, 5]), np.array([0.0, 6])
    vt = rng.normal(size=(4, A, 3))
    vr = Rotation.random(3 * A, random_state=2).as_quat().reshape(3, A, 4)
    vr[1, 0] = -(vr[0, 0] + 1e-4)  # nearly parallel, opposite sign
    vr = vr.astype(np.float32).astype(float)
    vs = rng.uniform(0.7, 1.3, (2, A, 3)).astype(np.float16).astype(float)
    clip = Clip("c", "/c", tt, vt, tr, vr, ts, vs, np.array([0, 2, 3, 5, 6]), tt)
    rest = naive.trs(rng.normal(size=(J, 3)), Rotation.random(J, random_state=3).as_quat(), np.ones((J, 3)))
    times = np.array([-1.0, 0, 0.5, 1, 1.7, 2, 3.3, 4, 4.5, 6, 6.9, 7, 9])
    a = PK.locals_at(clip, times, rest, trs=True, compiled=True)
    b = PK.locals_at(clip, times, rest, trs=True, compiled=False)
    for x, y in zip(a, b):
        np.testing.assert_allclose(y, x, rtol=0, atol=1e-13)


def test_chain_bounds_numpy_path_equals_the_kernel():
    """The continuous certificate's chain recursion, vectorised (small clips) against the kernel."""
    rng = np.random.default_rng(8)
    rig, clip, _ = random_rig(rng, J=7, n=300, F=6, scale=True)
    fac = C.factor_bounds(clip, clip.times, rig.rest_local)
    off, pj, pd, pair_part = rig.paths()
    bd = rig.bounds
    I, M = len(clip.times) - 1, len(bd.pj_joint)
    outs = []
    for compiled in (True, False):
        e = [np.zeros((I, M)) for _ in range(5)]
        IV.chain_bounds(fac["L0"], fac["L1"], fac["Li0"], fac["Li1"], fac["fw"], fac["iv"], fac["dt"], fac["eps"],
                        off, pj, pd, bd.pj_center, bd.pj_radius, pair_part, bd.part_centers, *e, compiled=compiled)
        outs.append(e)
    assert M > 10 and np.diff(off).max() >= 3
    for x, y in zip(*outs):
        np.testing.assert_allclose(y, x, rtol=1e-12, atol=1e-12)


def test_trs_matrices_match_naive():
    rng = np.random.default_rng(5)
    t, q, s = rng.normal(size=(7, 3)), Rotation.random(7, random_state=5).as_quat(), rng.uniform(0.5, 2, (7, 3))
    np.testing.assert_allclose(PK.trs_matrices(t, q, s), naive.trs(t, q, s), atol=1e-12)


@pytest.mark.parametrize("compiled", [True, False])
def test_factor_terms_match_naive(compiled):
    """The continuous certificate's per-(interval, joint) factor bounds, compiled, against their
    numpy transcription: random rotations, non-uniform and sign-changing scales, a joint the clip
    does not animate (its rest transform sheared), one zero scale."""
    rng = np.random.default_rng(11)
    T, J = 9, 5
    anim = np.array([0, 1, 3, 4])
    rest = naive.trs(rng.normal(size=(J, 3)), Rotation.random(J, random_state=3).as_quat(), rng.uniform(0.5, 2, (J, 3)))
    rest[2, 0, 1] += 0.3  # sheared: not a similarity
    t = rng.normal(size=(T, len(anim), 3))
    q = Rotation.random(T * len(anim), random_state=4).as_quat().reshape(T, len(anim), 4) * rng.uniform(0.9, 1.1, (T, len(anim), 1))
    s = rng.uniform(0.5, 1.5, (T, len(anim), 3))
    s[:, 1] = s[:, 1, :1]          # uniform
    s[4, 2, 1] *= -1               # a sign change
    s[6, 3, 0] = 0.0               # a zero scale
    s[:3, 0] = s[0, 0]             # constant over the first intervals
    L = np.repeat(rest[None], T, 0)
    L[:, anim] = naive.trs(t, q / np.linalg.norm(q, axis=-1, keepdims=True), s)
    got = IV.factor_terms(L, t, q, s, anim, rest, C.OMEGA_MARGIN, C.ALPHA_MARGIN, compiled=compiled)
    want = naive.factor_terms(L, t, q, s, anim, rest, C.OMEGA_MARGIN, C.ALPHA_MARGIN)
    ok = np.abs(np.linalg.det(L[..., :3, :3])) > 1e-12
    np.testing.assert_allclose(got[0][ok], want[0][ok], rtol=1e-9, atol=1e-9)
    for g, w, name in zip(got[1:], want[1:], ("fw", "iv", "dt", "eps", "iso")):
        np.testing.assert_array_equal(np.isinf(g), np.isinf(w), err_msg=name)
        fin = np.isfinite(w)
        np.testing.assert_allclose(np.asarray(g)[fin], np.asarray(w)[fin], rtol=1e-9, atol=1e-12, err_msg=name)
    assert np.isinf(got[2][5:7, 4]).all() and np.isinf(got[2][3:5, 3]).all() and not got[5][:, 2].any()


# -- bounds: soundness against dense brute force ----------------------------------------------
def _random_tree_skin(rng, J, n):
    """The random skin every random rig here shares: a joint tree of ``J`` joints (rest
    translations, no rotation), its bind pose, ``n`` points round the joints skinned to their 4
    nearest (weights falling off with distance, some dropped), and one part per joint (its
    strongest points): ``(parents, rest_t, rest, bind, pts, ji, jw, order, voff)``."""
    parents = np.array([-1] + [int(rng.integers(0, j)) for j in range(1, J)])
    rest_t = rng.normal(size=(J, 3))
    rest_t[0] = 0
    rest = naive.trs(rest_t, np.tile([0, 0, 0, 1.0], (J, 1)), np.ones((J, 3)))
    bind = naive.compose(rest, parents)
    pts = (bind[rng.integers(0, J, n), :3, 3] + 0.4 * rng.normal(size=(n, 3))).astype(np.float32)
    d = np.linalg.norm(pts[:, None] - bind[None, :, :3, 3], axis=2)
    ji = np.argsort(d, 1)[:, :4].astype(np.int32)
    w = np.exp(-np.take_along_axis(d, ji, 1) ** 2) * (rng.random((n, 4)) < 0.8)
    w[:, 0] += 1e-3
    jw = (w / w.sum(1, keepdims=True)).astype(np.float32)
    owner = ji[:, 0]
    order = np.argsort(owner, kind="stable")
    voff = np.searchsorted(owner[order], np.arange(J + 1))
    return parents, rest_t, rest, bind, pts, ji, jw, order, voff


def random_rig(rng, J=6, n=400, F=6, angle=0.8, scale=False, tight=True):
    """A random joint tree, random points skinned to 1-4 nearby joints, one part per joint
    (strongest joint), a clip of F frames of random rotations (up to ``angle`` rad per frame),
    translations and (``scale``) non-uniform scales; spheres fitted to the frames only."""
    parents, rest_t, rest, bind, pts, ji, jw, order, voff = _random_tree_skin(rng, J, n)
    times = np.arange(F, dtype=float)
    rots = Rotation.random(J, random_state=int(rng.integers(1 << 30)))
    q = np.empty((F, J, 4))
    cur = Rotation.identity(J)
    for f in range(F):
        q[f] = cur.as_quat()
        cur = Rotation.from_rotvec(rng.normal(size=(J, 3)) * angle / 2) * cur
    del rots
    t = rest_t[None] + 0.2 * rng.normal(size=(F, J, 3))
    # animated uniform scales (non-uniform ones make the certificate conservative: see continuous())
    s = np.ones((F, J, 3)) if not scale else np.repeat(rng.uniform(0.8, 1.25, size=(F, J, 1)), 3, 2).astype(np.float16).astype(float)
    clip = Clip("c", "/c", times, t, times, q.astype(np.float32).astype(float), times, s, np.arange(J), times)
    skel = naive.compose(naive.trs(t, clip.vr, s), parents)
    y = naive.naive_lbs(pts, ji, jw, skel @ np.linalg.inv(bind))
    centers = np.zeros((J, 3))
    radii = np.zeros(J)
    for p in range(J):
        vs = order[voff[p]:voff[p + 1]]
        loc = np.einsum("fij,fvj->fvi", np.linalg.inv(skel[:, p]), np.concatenate([y[:, vs], np.ones((F, len(vs), 1))], 2))[..., :3]
        lo, hi = loc.reshape(-1, 3).min(0), loc.reshape(-1, 3).max(0)
        centers[p] = (lo + hi) / 2 + (0.3 * rng.normal(size=3) if tight else 0)
        radii[p] = np.linalg.norm(loc - centers[p], axis=2).max() * (1 + (0 if tight else 0.3))
    rig = C.Rig(pts, ji, jw, np.eye(4), bind, rest, parents, np.arange(J), centers, radii, voff, order)
    return rig, clip, skel


def _dense(rig, clip, t0, t1, steps=64):
    """Stage distances of every part's farthest vertex minus its radius at ``steps`` sub-steps
    (naive: scipy-free slerp, T R S, LBS by definition)."""
    out = []
    for a in np.linspace(0, 1, steps + 1)[1:-1]:
        tt = t0 + a * (t1 - t0)
        i = int(np.floor(tt))
        f = tt - i
        q = naive.slerp(clip.vr[i], clip.vr[i + 1], f)
        t = (1 - f) * clip.vt[i] + f * clip.vt[i + 1]
        s = _half_lerp(clip.vs[i], clip.vs[i + 1], f)
        skel = naive.compose(naive.trs(t, q, s)[None], rig.parents)[0]
        y = naive.naive_lbs(rig.points, rig.joint_indices, rig.joint_weights, (skel @ rig.inv_bind)[None])[0]
        ex = np.zeros(rig.P)
        for p in range(rig.P):
            vs = rig.verts[rig.vert_offsets[p]:rig.vert_offsets[p + 1]]
            N = skel[rig.part_joint[p]]
            c = N[:3, :3] @ rig.part_centers[p] + N[:3, 3]
            R = rig.part_radii[p] * np.linalg.norm(N[:3, :3], axis=0).max()
            ex[p] = (np.linalg.norm(y[vs] - c, axis=1).max() - R) / R if len(vs) else -1
        out.append(ex)
    return np.array(out)  # (steps - 1, P) relative excess


@pytest.mark.parametrize("seed,scale", [(0, False), (1, False), (2, True), (3, False), (4, True)])
def test_continuous_certificate_is_sound_against_dense_brute_force(seed, scale, monkeypatch):
    monkeypatch.setattr(C, "BATCHED_MIN_PAIRS", 0)  # the batched levels B and C, as on a large asset
    rng = np.random.default_rng(seed)
    rig, clip, skel = random_rig(rng, scale=scale, tight=seed % 2 == 0 and not scale)
    # relative tolerance 1e-6: above float32 quaternion noise (1e-7), below the validator's 1e-5
    s = C.sampled(rig, skel, 0.0, 1e-6)
    ok = ~(s.bound > s.spheres[..., 3] * (1 + 1e-6))
    c = C.continuous(rig, clip, clip.times, s.bound, ok, 0.0, 1e-6)
    certified = c.status <= 2
    failed = c.status == 3
    seen_fail = False
    for i in range(len(clip.times) - 1):
        ex = _dense(rig, clip, clip.times[i], clip.times[i + 1]).max(0)
        assert not (certified[i] & (ex > 1e-6)).any(), (i, ex[certified[i]])  # never a false certificate
        seen_fail |= bool((ex > 1e-3).any())
    for f in c.failures:  # a reported failure is real: at its time its vertex is outside
        if f["definite"]:
            d = _dense_at(rig, clip, f["time"], f["part"], f["vertex"])
            assert d == pytest.approx(f["excess"], abs=1e-6 * f["radius"]) and d > 0
    assert c.status.size and certified.mean() > 0.3  # the bounds are not vacuous


def _dense_at(rig, clip, tt, p, v):
    """Stage distance minus radius of vertex ``v`` of part ``p`` at time ``tt`` (naive)."""
    i = min(int(np.floor(tt)), len(clip.times) - 2)
    f = tt - i
    skel = naive.compose(naive.trs((1 - f) * clip.vt[i] + f * clip.vt[i + 1], naive.slerp(clip.vr[i], clip.vr[i + 1], f),
                                   _half_lerp(clip.vs[i], clip.vs[i + 1], f))[None], rig.parents)[0]
    y = naive.naive_lbs(rig.points[v:v + 1], rig.joint_indices[v:v + 1], rig.joint_weights[v:v + 1],
                        (skel @ rig.inv_bind)[None])[0, 0]
    N = skel[rig.part_joint[p]]
    return np.linalg.norm(y - (N[:3, :3] @ rig.part_centers[p] + N[:3, 3])) - \
        rig.part_radii[p] * np.linalg.norm(N[:3, :3], axis=0).max()


def _half_lerp(s0, s1, f):
    h = np.float16  # UsdSkel lerps half3 scales in half precision
    return (h(h((1 - f) * s0) + h(f * s1))).astype(np.float64)


@pytest.mark.parametrize("min_pairs", [0, 10 ** 9])  # the batched levels B and C, and the reference loop
def test_a_vertex_leaving_only_between_samples_is_caught_with_its_interval(min_pairs, monkeypatch):
    """Two joints; the child swings +0.9 rad then -0.9 rad: the straight pose half-way is outside a
    sphere fitted to the two frames around a centre below the child's pivot (the tip is 1.368 from
    it at both frames and 1.5 when straight)."""
    parents = np.array([-1, 0])
    rest = naive.trs([[0, 0, 0], [0, 1, 0]], [[0, 0, 0, 1.0]] * 2, np.ones((2, 3)))
    bind = naive.compose(rest, parents)
    y = np.linspace(1.0, 2.0, 11)
    pts = np.c_[np.zeros_like(y), y, np.zeros_like(y)].astype(np.float32)
    ji = np.c_[np.ones(11, np.int32), np.zeros(11, np.int32)]
    jw = np.c_[np.ones(11), np.zeros(11)].astype(np.float32)
    qz = Rotation.from_rotvec([[0, 0, 0.9], [0, 0, -0.9]]).as_quat()
    times = np.array([0.0, 1.0])
    clip = Clip("swing", "/swing", times, np.tile([[[0, 0, 0], [0, 1, 0]]], (2, 1, 1)).astype(float), times,
                    np.stack([np.tile([0, 0, 0, 1.0], (2, 1)), np.tile([0, 0, 0, 1.0], (2, 1))], 0), times,
                    np.ones((2, 2, 3)), np.array([0, 1]), times)
    clip.vr[:, 1] = qz
    # part 0 belongs to the root joint and holds the child's vertices
    skel = naive.compose(naive.trs(clip.vt, clip.vr, clip.vs), parents)
    yk = naive.naive_lbs(pts, ji, jw, skel @ np.linalg.inv(bind))
    c = np.array([0.0, 0.5, 0.0])
    r = np.linalg.norm(yk - c, axis=2).max() * (1 + 1e-6)
    rig = C.Rig(pts, ji, jw, np.eye(4), bind, rest, parents, [0], c[None], [r], [0, 11], np.arange(11))
    monkeypatch.setattr(C, "BATCHED_MIN_PAIRS", min_pairs)
    s = C.sampled(rig, skel, 0.0, 1e-6)
    ok = ~(s.bound > s.spheres[..., 3] * (1 + 1e-6))
    assert ok.all()  # both samples inside
    res = C.continuous(rig, clip, times, s.bound, ok, 0.0, 1e-6)
    assert res.status[0, 0] == 3 and len(res.failures) == 1
    f = res.failures[0]
    assert (f["t0"], f["t1"]) == (0.0, 1.0) and f["excess"] > 0.05 and 0 <= f["vertex"] < 11
    assert abs(f["time"] - 0.5) <= 0.1


def test_pose_bounds_hold_on_random_poses():
    """Tests K and D are upper bounds of the farthest skinned vertex (any pose, any weights)."""
    rng = np.random.default_rng(7)
    for trial in range(4):
        rig, clip, skel = random_rig(rng)
        wild = naive.compose(naive.trs(rng.normal(size=(10, 6, 3)), Rotation.random(60, random_state=trial)
                                       .as_quat().reshape(10, 6, 4), rng.uniform(0.5, 2, (10, 6, 3))), rig.parents)
        for poses in (skel, wild):
            sph, kb, db = B.pose_bounds(poses, rig.bounds)
            y = naive.naive_lbs(rig.points, rig.joint_indices, rig.joint_weights, poses @ rig.inv_bind)
            for p in range(rig.P):
                vs = rig.verts[rig.vert_offsets[p]:rig.vert_offsets[p + 1]]
                far = np.linalg.norm(y[:, vs] - sph[:, p, None, :3], axis=2).max(1)
                assert (far <= kb[:, p] * (1 + 1e-9)).all() and (far <= db[:, p] * (1 + 1e-9)).all()


def test_pareto_set_keeps_every_maximiser():
    rng = np.random.default_rng(8)
    d, w = rng.random(300), rng.random((300, 3)) * (rng.random((300, 3)) < 0.5)
    keep = B.pareto_set(d, w, limit=10 ** 6)
    for _ in range(200):
        e = rng.random(4)
        val = e[0] * d + w @ e[1:]
        assert val[keep].max() == pytest.approx(val.max())


# -- the continuous certificate's levels B and C, batched (runtime.kernels.subdivide) ----------
def test_chord_nodes_equals_chord_tasks():
    """The batched per-vertex chord bound (one kernel over all nodes, J-space transforms built in
    the kernel from skeleton and skinning transforms) against the numpy reference
    ``interval.chord_tasks`` on the same nodes, and against its definition by brute force."""
    from colossus.runtime.kernels import subdivide as SD
    rng = np.random.default_rng(31)
    rig, clip, skel = random_rig(rng, scale=True)
    I = len(clip.times) - 1
    ibg = rig.inv_bind @ rig.geom_bind
    ts = np.r_[clip.times, clip.times[:-1] + 0.37, clip.times[:-1] + 0.5]
    sk, skin = SD.pose_at(clip, ts, rig.rest_local, rig.parents, rig.topo, ibg)
    np.testing.assert_allclose(skin, sk @ ibg, rtol=0, atol=1e-12)
    N = 40
    part = rng.integers(0, rig.P, N)
    ta, tb = rng.integers(0, len(ts), N), rng.integers(0, len(ts), N)
    row = rng.integers(0, 7, N)
    scale = rng.random(N)
    drow = rng.random((7, len(rig.bind))) * 0.1
    prow = rng.random((7, len(rig.bind))) * 0.01
    bd = rig.bounds
    got = SD.chord_nodes(rig.points, rig.joint_indices, rig.joint_weights, rig.vert_offsets, rig.verts,
                         bd.part_joint, bd.pj_offsets, bd.pj_joint, bd.part_centers, sk, skin, part, ta, tb, row,
                         scale, drow, prow)
    # the reference: J-space folded transforms per (time, part joint), one task per node
    mats = np.stack([rig.joint_space_mats(sk[[ta[n], tb[n]]], rig.part_joint[part[n]]) for n in range(N)])
    mats = mats.reshape(2 * N, len(rig.bind), 12)
    want = IV.chord_tasks(rig.points, rig.joint_indices, rig.joint_weights, mats, rig.vert_offsets, rig.verts,
                          bd.part_centers, part, 2 * np.arange(N), 2 * np.arange(N) + 1, row, scale, drow, prow)
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=1e-12, atol=1e-12)
    # by definition: every vertex at both ends, its weighted deviation, the largest sum
    for n in range(N):
        vs = rig.verts[rig.vert_offsets[part[n]]:rig.vert_offsets[part[n] + 1]]
        J = rig.part_joint[part[n]]
        ends = [naive.naive_lbs(rig.points[vs], rig.joint_indices[vs], rig.joint_weights[vs],
                                (np.linalg.inv(sk[t, J]) @ sk[t] @ ibg)[None])[0] for t in (ta[n], tb[n])]
        d = [np.linalg.norm(e - rig.part_centers[part[n]], axis=1) for e in ends]
        x = scale[n] * drow[row[n]] + prow[row[n]]
        dev = (np.abs(rig.joint_weights[vs]) * x[rig.joint_indices[vs]]).sum(1)
        u = (np.maximum(d[0], d[1]) + dev).max()
        assert u <= got[0][n] <= u * (1 + 3e-12)  # the bound, padded by ROUND, and no more
        assert got[2][n] == pytest.approx(d[0].max(), rel=1e-12) and got[4][n] == pytest.approx(d[1].max(), rel=1e-12)


@pytest.mark.parametrize("seed,scale,growth", [(0, False, False), (1, False, True), (2, True, False),
                                               (4, True, True), (5, False, False)])
def test_batched_refine_decides_as_the_reference(seed, scale, growth, monkeypatch):
    """Levels B and C batched (``certify.BATCHED``) against the reference loop: the same status
    of every (interval, part), the same subdivisions and failures, the same bounds to rounding."""
    rng = np.random.default_rng(seed)
    rig, clip, skel = random_rig(rng, scale=scale, tight=True)
    s = C.sampled(rig, skel, 0.0, 1e-6)
    ok = ~(s.bound > s.spheres[..., 3] * (1 + 1e-6))
    kw = dict(growth=True, max_depth=5, rho=rig.part_radii * 0.98) if growth else {}
    res = {}
    for batched in (False, True):
        monkeypatch.setattr(C, "BATCHED", batched)
        monkeypatch.setattr(C, "BATCHED_MIN_PAIRS", 0)
        res[batched] = C.continuous(rig, clip, clip.times, s.bound, ok, 0.0, 1e-6, **kw)
    a, b = res[False], res[True]
    assert a.subdivided > 0
    np.testing.assert_array_equal(a.status, b.status)
    assert a.subdivided == b.subdivided
    np.testing.assert_allclose(b.bound, a.bound, rtol=1e-12)
    assert [(f["interval"], f["part"], f["definite"], f["vertex"]) for f in a.failures] == \
        [(f["interval"], f["part"], f["definite"], f["vertex"]) for f in b.failures]
    for f, g in zip(a.failures, b.failures):
        assert f["excess"] == pytest.approx(g["excess"], rel=1e-9, abs=1e-12)


# -- the sampled proof's exact tier by chunks (runtime.kernels.farthest) -------------------------
def _chunk_bounds_naive(rig, m, centers, ch):
    """``min(K_c, D_c)`` of :mod:`runtime.kernels.farthest` written out (numpy, unpadded)."""
    def n2(L):  # the Gershgorin bound of runtime.kernels.bounds._norm2
        return np.sqrt(np.abs(L.T @ L).sum(1).max())
    F = len(m)
    M = np.zeros((F, m.shape[1], 4, 4))
    M[..., :3, :] = m.reshape(F, -1, 3, 4)
    M[..., 3, 3] = 1
    out = np.zeros((F, len(ch.radius)))
    for p in range(rig.P):
        J = rig.part_joint[p]
        for c in range(ch.part_chunks[p], ch.part_chunks[p + 1]):
            o, r = np.r_[ch.center[c], 1.0], ch.radius[c]
            js = ch.joints[ch.joint_offsets[c]:ch.joint_offsets[c + 1]]
            wm = ch.jwmax[ch.joint_offsets[c]:ch.joint_offsets[c + 1]]
            for f in range(F):
                C = centers[f, p]
                yJ = (M[f, J] @ o)[:3]
                nJ = n2(M[f, J, :3, :3])
                K = ch.wabs[c] * max(np.linalg.norm((M[f, b] @ o)[:3] - C) + n2(M[f, b, :3, :3]) * r for b in js) \
                    + ch.wdev[c] * np.linalg.norm(C)
                D = np.linalg.norm(yJ - C) + nJ * r + ch.wdev[c] * (np.linalg.norm(yJ) + nJ * r) + sum(
                    w * (np.linalg.norm((M[f, b] @ o)[:3] - yJ) + n2(M[f, b, :3, :3] - M[f, J, :3, :3]) * r)
                    for b, w in zip(js, wm) if b != J)
                out[f, c] = min(K, D)
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_chunk_bounds_hold_against_brute_force_and_are_the_written_bound(seed):
    """The chunk bound ``min(K_c, D_c)`` is an upper bound of every chunk vertex's skinned distance
    (dense brute force, random rigs, wild poses with non-uniform scales), and it is the bound the
    docstring writes, to rounding (a bound loosened by 1 % fails here)."""
    from colossus.runtime.kernels import farthest as FA
    rng = np.random.default_rng(40 + seed)
    rig, clip, skel = random_rig(rng, scale=seed == 2)
    wild = naive.compose(naive.trs(rng.normal(size=(6, 6, 3)), Rotation.random(36, random_state=seed)
                                   .as_quat().reshape(6, 6, 4), rng.uniform(0.5, 2, (6, 6, 3))), rig.parents)
    ch = FA.chunk_data(rig.points, rig.joint_indices, rig.joint_weights, rig.vert_offsets, rig.verts, size=8)
    for poses in (skel, wild):
        m = rig.skin_mats(poses)
        centers = rng.normal(size=(len(poses), rig.P, 3))
        got = FA.chunk_bounds(m, centers, rig.part_joint, ch)
        want = _chunk_bounds_naive(rig, m, centers, ch)
        np.testing.assert_allclose(got, want, rtol=1e-9)
        assert (got >= want).all()
        y = naive.naive_lbs(rig.points, rig.joint_indices, rig.joint_weights, poses @ rig.inv_bind)
        part = np.repeat(np.arange(rig.P), np.diff(ch.part_chunks))
        for c in range(len(ch.radius)):
            vs = rig.verts[ch.pos[ch.pos_offsets[c]:ch.pos_offsets[c + 1]]]
            far = np.linalg.norm(y[:, vs] - centers[:, part[c], None], axis=2).max(1)
            assert (far <= got[:, c]).all()
            assert (far <= want[:, c] * (1 + 1e-9)).all()
        # the bound is not vacuous: pruning has something to work with
        assert (want < 1.5 * np.linalg.norm(y[:, rig.verts] - centers[:, np.repeat(np.arange(rig.P), np.diff(rig.vert_offsets))], axis=2).max()).mean() > 0.5


@pytest.mark.parametrize("n", [400, 30000])  # the one-thread and the threaded kernel
def test_chunk_search_equals_part_farthest(n):
    """The exact tier by chunks returns exactly ``part_farthest``'s distances and vertices (ties
    broken alike), for tight and random centres, an empty part, duplicated vertices (ties) and a
    NaN point."""
    from colossus.runtime.kernels import farthest as FA
    rng = np.random.default_rng(5)
    rig, clip, skel = random_rig(rng, n=n)
    pts = rig.points.copy()
    pts[rig.verts[rig.vert_offsets[1] + 3]] = pts[rig.verts[rig.vert_offsets[1] + 5]]  # a tie
    voff = rig.vert_offsets.copy()
    voff[2] = voff[3]  # part 2 empty, part 3 gets its vertices
    m = rig.skin_mats(skel)
    sph, _, _ = B.pose_bounds(skel, rig.bounds)
    for centers in (sph[..., :3], sph[..., :3] + rng.normal(size=sph[..., :3].shape)):
        todo = rng.random((len(skel), rig.P)) < 0.7
        ch = FA.chunk_data(pts, rig.joint_indices, rig.joint_weights, voff, rig.verts)
        d, v, skinned = FA.farthest(pts, rig.joint_indices, rig.joint_weights, m, voff, rig.verts, rig.part_joint,
                                    centers, todo, ch)
        d0, v0 = SK.part_farthest(pts, rig.joint_indices, rig.joint_weights, m, voff, rig.verts, centers, todo=todo)
        np.testing.assert_array_equal(v, v0)
        np.testing.assert_allclose(d, d0, rtol=1e-13)
        assert np.isnan(d[~todo]).all() and skinned <= (np.diff(voff)[None] * todo).sum()
    pts[rig.verts[0]] = np.nan  # its chunk's ball is NaN: never pruned
    with np.errstate(invalid="ignore"):
        ch = FA.chunk_data(pts, rig.joint_indices, rig.joint_weights, voff, rig.verts)
    d, v, _ = FA.farthest(pts, rig.joint_indices, rig.joint_weights, m, voff, rig.verts, rig.part_joint,
                          sph[..., :3], np.ones((len(skel), rig.P), bool), ch)
    assert np.isinf(d[:, 0]).all() and (v[:, 0] == rig.verts[0]).all()


def test_sampled_proof_is_the_same_with_the_chunk_search(monkeypatch):
    """``certify.sampled`` with the exact tier by chunks (``certify.CHUNKED``) and by whole parts:
    the same tiers, bounds, distances and vertices."""
    rng = np.random.default_rng(12)
    rig, clip, skel = random_rig(rng, n=2000)
    out = {}
    exact = rng.random((len(skel), rig.P)) < 0.5
    for chunked in (False, True):
        monkeypatch.setattr(C, "CHUNKED", chunked)
        out[chunked] = C.sampled(rig, skel, 0.0, 1e-6, exact=exact)
    a, b = out[False], out[True]
    np.testing.assert_array_equal(a.tier, b.tier)
    np.testing.assert_array_equal(a.vertex, b.vertex)
    np.testing.assert_allclose(b.dist, a.dist, rtol=1e-13)
    np.testing.assert_allclose(b.bound, a.bound, rtol=1e-13)


# -- dual-quaternion certificate (runtime.certify_dq) -------------------------------------------
def random_dq_rig(rng, J=6, n=300, F=6, angle=0.6, slack=0.15, world=None):
    """A random rig skinned by UsdSkel's DQS (naive_dqs), its spheres fitted to the frames (plus
    ``slack`` of the radius: the in-between poses may leave them)."""
    parents, rest_t, rest, bind, pts, ji, jw, order, voff = _random_tree_skin(rng, J, n)
    times = np.arange(F, dtype=float)
    q = np.empty((F, J, 4))
    cur = Rotation.random(J, random_state=int(rng.integers(1 << 30)))
    for f in range(F):
        q[f] = cur.as_quat()
        cur = Rotation.from_rotvec(rng.normal(size=(J, 3)) * angle / 2) * cur
    t = rest_t[None] + 0.2 * rng.normal(size=(F, J, 3))
    s = np.ones((F, J, 3))
    clip = Clip("c", "/c", times, t, times, q.astype(np.float32).astype(float), times, s, np.arange(J), times)
    skel = naive.compose(naive.trs(t, clip.vr, s), parents)
    y = naive.naive_dqs(pts, ji, jw, skel @ np.linalg.inv(bind))
    centers, radii = np.zeros((J, 3)), np.zeros(J)
    for p in range(J):
        vs = order[voff[p]:voff[p + 1]]
        loc = np.einsum("fij,fvj->fvi", np.linalg.inv(skel[:, p]), np.concatenate([y[:, vs], np.ones((F, len(vs), 1))], 2))[..., :3]
        lo, hi = loc.reshape(-1, 3).min(0), loc.reshape(-1, 3).max(0)
        centers[p] = (lo + hi) / 2
        radii[p] = np.linalg.norm(loc - centers[p], axis=2).max() * (1 + slack) + 1e-3
    rig = C.Rig(pts, ji, jw, np.eye(4), bind, rest, parents, np.arange(J), centers, radii, voff, order,
                world=np.eye(4) if world is None else world, skinning_method="dualQuaternion")
    return rig, clip, skel


def _dense_dq(rig, clip, t0, t1, steps=48):
    """(steps - 1, P) joint-space farthest distance of every part at sub-steps of [t0, t1]
    (naive slerp and T R S; the skin by usd-core's own ``UsdSkel.SkinPoints(dualQuaternion)``)."""
    out = []
    for a in np.linspace(0, 1, steps + 1)[1:-1]:
        tt = t0 + a * (t1 - t0)
        i = min(int(np.floor(tt)), len(clip.times) - 2)
        f = tt - i
        skel = naive.compose(naive.trs((1 - f) * clip.vt[i] + f * clip.vt[i + 1], naive.slerp(clip.vr[i], clip.vr[i + 1], f),
                                       _half_lerp(clip.vs[i], clip.vs[i + 1], f))[None], rig.parents)[0]
        y = _usd_dqs(rig.points, rig.joint_indices, rig.joint_weights, (skel @ rig.inv_bind)[None], np.eye(4))[0]
        far = np.zeros(rig.P)
        for p in range(rig.P):
            vs = rig.verts[rig.vert_offsets[p]:rig.vert_offsets[p + 1]]
            N = skel[rig.part_joint[p]]
            loc = (y[vs] - N[:3, 3]) @ np.linalg.inv(N[:3, :3]).T
            far[p] = np.linalg.norm(loc - rig.part_centers[p], axis=1).max() if len(vs) else 0
        out.append(far)
    return np.array(out)


@pytest.mark.parametrize("seed", range(20))
def test_dq_certificate_is_sound_against_dense_brute_force(seed):
    """20 random DQS rigs: no certified interval has a dense in-between pose outside a sphere, and
    the growth bound (a joint-space bound of the farthest vertex) is never below the dense maximum."""
    rng = np.random.default_rng(300 + seed)
    rig, clip, skel = random_dq_rig(rng, angle=0.3 + 0.05 * (seed % 5), slack=0.05 + 0.05 * (seed % 4))
    s = C.sampled(rig, skel, 0.0, 1e-6)
    assert (s.tier == 2).all()  # DQS parts are skinned exactly at the samples
    ok = ~(s.dist > s.spheres[..., 3] * (1 + 1e-6))
    c = CDQ.certificate(rig, clip, clip.times, s.bound, ok, 0.0, 1e-6)
    g = CDQ.certificate(rig, clip, clip.times, s.bound, ok, 0.0, 0.0, rho=np.zeros(rig.P), growth=True, max_depth=5)
    certified = (c.status == 1) | (c.status == 2)
    for i in range(len(clip.times) - 1):
        far = _dense_dq(rig, clip, clip.times[i], clip.times[i + 1]).max(0)
        assert not (certified[i] & (far > rig.part_radii * (1 + 1e-6))).any(), (i, far, rig.part_radii)
        assert np.all(far <= g.bound[i] * (1 + 1e-9)), (i, far, g.bound[i])
    for f in c.failures:
        if f["definite"]:
            assert f["excess"] > 0
    assert certified.mean() > 0.3  # the bound is not vacuous


def test_dq_bound_is_tight_enough_that_one_percent_less_is_caught():
    """The dense check has teeth: on some interval the growth bound is within 1% of the dense
    maximum, so a bound 1% smaller (an unsound one) would fail the soundness test above."""
    rng = np.random.default_rng(11)
    rig, clip, skel = random_dq_rig(rng, angle=0.2)
    s = C.sampled(rig, skel, 0.0, 1e-6)
    g = CDQ.certificate(rig, clip, clip.times, s.bound, np.ones_like(s.bound, bool), 0.0, 0.0,
                     rho=np.zeros(rig.P), growth=True, max_depth=8)
    caught = False
    for i in range(len(clip.times) - 1):
        far = _dense_dq(rig, clip, clip.times[i], clip.times[i + 1], steps=64).max(0)
        ends = np.maximum(s.dist[i], s.dist[i + 1])  # joint = stage space here (rigid, world = I)
        far = np.maximum(far, ends)
        assert np.all(far <= g.bound[i] * (1 + 1e-9))
        caught |= bool(np.any(0.99 * g.bound[i] < far))
    assert caught


def test_dq_vertex_leaving_only_between_samples_by_a_rotation_is_caught_with_its_interval():
    """A two-joint DQS limb whose child swings +0.9 rad then -0.9 rad: at both samples the tip is
    inside the root's sphere, straight half-way it is outside; the interval is reported."""
    parents = np.array([-1, 0])
    rest = naive.trs([[0, 0, 0], [0, 1, 0]], [[0, 0, 0, 1.0]] * 2, np.ones((2, 3)))
    bind = naive.compose(rest, parents)
    y = np.linspace(1.0, 2.0, 11)
    pts = np.c_[np.zeros_like(y), y, np.zeros_like(y)].astype(np.float32)
    ji = np.c_[np.ones(11, np.int32), np.zeros(11, np.int32)]
    jw = np.c_[np.full(11, 0.8), np.full(11, 0.2)].astype(np.float32)  # blended: DQS, not LBS, decides
    qz = Rotation.from_rotvec([[0, 0, 0.9], [0, 0, -0.9]]).as_quat()
    times = np.array([0.0, 1.0])
    clip = Clip("swing", "/swing", times, np.tile([[[0, 0, 0], [0, 1, 0]]], (2, 1, 1)).astype(float), times,
                np.stack([np.tile([0, 0, 0, 1.0], (2, 1)), np.tile([0, 0, 0, 1.0], (2, 1))], 0), times,
                np.ones((2, 2, 3)), np.array([0, 1]), times)
    clip.vr[:, 1] = qz
    skel = naive.compose(naive.trs(clip.vt, clip.vr, clip.vs), parents)
    yk = naive.naive_dqs(pts, ji, jw, skel @ np.linalg.inv(bind))
    c = np.array([0.0, 0.5, 0.0])
    r = np.linalg.norm(yk - c, axis=2).max() * (1 + 1e-6)
    rig = C.Rig(pts, ji, jw, np.eye(4), bind, rest, parents, [0], c[None], [r], [0, 11], np.arange(11),
                skinning_method="dualQuaternion")
    s = C.sampled(rig, skel, 0.0, 1e-6)
    ok = ~(s.bound > s.spheres[..., 3] * (1 + 1e-6))
    assert ok.all()  # both samples inside
    mid = naive.naive_dqs(pts, ji, jw, naive.compose(naive.trs(clip.vt[:1], np.tile([0, 0, 0, 1.0], (1, 2, 1)),
                                                               clip.vs[:1]), parents) @ np.linalg.inv(bind))
    assert np.linalg.norm(mid[0] - c, axis=1).max() > r * 1.05  # outside half-way (by DQS)
    res = CDQ.certificate(rig, clip, times, s.bound, ok, 0.0, 1e-6)
    assert res.status[0, 0] == 3 and len(res.failures) == 1
    f = res.failures[0]
    assert (f["t0"], f["t1"]) == (0.0, 1.0) and f["excess"] > 0.05 and 0 <= f["vertex"] < 11 and f["definite"]
    assert abs(f["time"] - 0.5) <= 0.1


@pytest.mark.parametrize("case", ["animated_scale", "mirrored_bind", "negative_weight"])
def test_dq_certificate_fails_closed_outside_its_hypotheses(case):
    """Where the DQS Lipschitz bound's hypotheses fail (scales that change between samples, a
    mirrored skinning transform, negative weights) nothing is certified: undecided, with a reason."""
    rng = np.random.default_rng(21)
    rig, clip, skel = random_dq_rig(rng, angle=0.2, slack=0.5)
    if case == "animated_scale":
        clip.vs[1:] = np.float16(1.25)
        skel = naive.compose(naive.trs(clip.vt, clip.vr, clip.vs), rig.parents)
    elif case == "mirrored_bind":
        bind = rig.bind.copy()
        bind[2, :3, 0] *= -1
        rig = C.Rig(rig.points, rig.joint_indices, rig.joint_weights, rig.geom_bind, bind, rig.rest_local, rig.parents,
                    rig.part_joint, rig.part_centers, rig.part_radii, rig.vert_offsets, rig.verts,
                    skinning_method="dualQuaternion")
    else:
        jw = rig.joint_weights.copy()
        jw[0, 1] = -0.01
        rig = C.Rig(rig.points, rig.joint_indices, jw, rig.geom_bind, rig.bind, rig.rest_local, rig.parents,
                    rig.part_joint, rig.part_centers, rig.part_radii, rig.vert_offsets, rig.verts,
                    skinning_method="dualQuaternion")
    s = C.sampled(rig, skel, 0.0, 1e-6)
    c = CDQ.certificate(rig, clip, clip.times, s.bound, np.ones_like(s.bound, bool), 0.0, 1e-6)
    bad = np.ones(len(clip.times) - 1, bool)
    if case == "animated_scale":
        bad[1:] = False  # only the first interval's scales change
    assert (c.status[bad] == 4).all() and not ((c.status[bad] == 1) | (c.status[bad] == 2)).any()
    assert all("hypotheses" in f.get("reason", "") for f in c.failures if f["interval"] in np.flatnonzero(bad))


@pytest.mark.parametrize("seed", range(10))
def test_dq_static_bound_is_sound_across_scale_steps_and_flips(seed):
    """Item 9 of :mod:`runtime.certify_dq`: on random DQS rigs whose scales change between samples
    (UsdSkel's half-precision lerp, where the Lipschitz bound does not apply) and whose joints turn
    far enough to flip hemispheres, the growth bound is finite and never below the dense maximum."""
    rng = np.random.default_rng(900 + seed)
    rig, clip, _ = random_dq_rig(rng, angle=0.6 + 0.1 * (seed % 3))
    J = len(rig.bind)
    clip.vs[:] = np.float16(1.0 + 0.3 * rng.random((len(clip.times), J, 1)) * (rng.random((1, J, 1)) < 0.5))
    skel = naive.compose(naive.trs(clip.vt, clip.vr, clip.vs), rig.parents)
    s = C.sampled(rig, skel, 0.0, 1e-6)
    g = CDQ.certificate(rig, clip, clip.times, s.bound, np.ones_like(s.bound, bool), 0.0, 0.0,
                        rho=np.zeros(rig.P), growth=True, max_depth=5)
    assert np.isfinite(g.bound).all()
    for i in range(len(clip.times) - 1):
        far = _dense_dq(rig, clip, clip.times[i], clip.times[i + 1], steps=32).max(0)
        assert np.all(far <= g.bound[i] * (1 + 1e-9)), (i, far, g.bound[i])


def test_dq_static_bound_is_exact_for_rigid_vertices_so_one_percent_less_is_caught():
    """Item 9's bound is ``|p - o|`` for a part whose vertices follow its own joint alone (and
    whose joint is not scaled): with scales changing elsewhere it is the dense maximum itself, so a
    static bound 1% smaller would fail the soundness test above."""
    rng = np.random.default_rng(5)
    rig, clip, _ = random_dq_rig(rng, angle=0.3)
    jw = rig.joint_weights.copy()
    ji = rig.joint_indices.copy()
    p0 = rig.verts[rig.vert_offsets[0]:rig.vert_offsets[1]]
    ji[p0] = rig.part_joint[0]
    jw[p0] = [1, 0, 0, 0]
    rig = C.Rig(rig.points, ji, jw, rig.geom_bind, rig.bind, rig.rest_local, rig.parents, rig.part_joint,
                rig.part_centers, rig.part_radii, rig.vert_offsets, rig.verts, skinning_method="dualQuaternion")
    J = len(rig.bind)
    chain = {0} | set(_ancestors(rig.parents, 0))
    scaled = np.array([j for j in range(J) if j not in chain])
    clip.vs[:, scaled] = np.float16(1.0 + 0.2 * rng.random((len(clip.times), len(scaled), 1)))
    skel = naive.compose(naive.trs(clip.vt, clip.vr, clip.vs), rig.parents)
    s = C.sampled(rig, skel, 0.0, 1e-6)
    g = CDQ.certificate(rig, clip, clip.times, s.bound, np.ones_like(s.bound, bool), 0.0, 0.0,
                        rho=np.zeros(rig.P), growth=True, max_depth=5)
    far = np.array([_dense_dq(rig, clip, clip.times[i], clip.times[i + 1], steps=16).max(0)
                    for i in range(len(clip.times) - 1)])
    assert np.all(far[:, 0] <= g.bound[:, 0] * (1 + 1e-9))
    assert np.any(0.99 * g.bound[:, 0] < far[:, 0])
    fac = C.factor_bounds(clip, clip.times, rig.rest_local)
    assert (fac["eps"] > 0).any(axis=(1, 2)).all()  # every interval steps: only item 9 applies


def _ancestors(parents, j):
    out = []
    while parents[j] >= 0:
        j = int(parents[j])
        out.append(j)
    return out


# -- blend shapes (the pre-pass of the one kernel) ---------------------------------------------
def _random_shapes(rng, n, S=4, F=6, inbetweens=True):
    """Random blend shapes (sparse and dense, with in-betweens at weights below 0, inside (0, 1)
    and above 1) and per-frame weights in [-1.5, 2.5]: ``(shapes, weights)``, shapes as
    ``(name, indices, offsets, [(weight, offsets)])``."""
    shapes = []
    for s in range(S):
        dense = s == 0
        idx = np.arange(n) if dense else np.sort(rng.choice(n, size=max(1, n // 3), replace=False))
        off = rng.normal(size=(len(idx), 3)).astype(np.float32)
        ib = []
        if inbetweens and s % 2 == 1:
            for w in rng.choice([-0.5, 0.25, 0.5, 0.8, 1.5], size=int(rng.integers(1, 4)), replace=False):
                ib.append((float(w), rng.normal(size=(len(idx), 3)).astype(np.float32)))
        shapes.append((f"shape{s}", idx, off, ib))
    W = rng.uniform(-1.5, 2.5, size=(F, S))
    W[0] = 0.0
    W[1, 0] = 0.0
    W[2, :] = [0.5, 0.25, 1.0, -0.5][:S]  # exactly on knots
    return shapes, W


def _kernel_shapes(shapes, n):
    from colossus.pipeline.model import BlendShape, kernel_shapes

    return kernel_shapes([BlendShape(nm, i, o, tuple(ib)) for nm, i, o, ib in shapes], n)


def _usd_shaped_skin(pts, ji, jw, m, G, shapes, W, method="classicLinear"):
    """usd-core's own blend shapes (``UsdSkel.BlendShapeQuery``: sub-shape weights,
    ``ComputeDeformedPoints``) then its own skinning (``UsdSkel.SkinPoints``), every frame."""
    from pxr import Sdf, UsdGeom

    st = Usd.Stage.CreateInMemory()
    UsdSkel.Root.Define(st, "/R")
    mesh = UsdGeom.Mesh.Define(st, "/R/M")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pts)))
    targets = []
    for name, idx, off, ib in shapes:
        bs = UsdSkel.BlendShape.Define(st, f"/R/M/{name}")
        bs.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(off)))
        bs.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(np.asarray(idx, dtype=np.int32)))
        for k, (w, o) in enumerate(ib):
            x = bs.CreateInbetween(f"ib{k}")
            x.SetWeight(w)
            x.SetOffsets(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(o)))
        targets.append(Sdf.Path(f"/R/M/{name}"))
    b = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    b.CreateBlendShapesAttr([s[0] for s in shapes])
    b.CreateBlendShapeTargetsRel().SetTargets(targets)
    q = UsdSkel.BlendShapeQuery(b)
    offsets, indices = q.ComputeSubShapePointOffsets(), q.ComputeBlendShapePointIndices()
    g = Gf.Matrix4d(*np.asarray(G).T.reshape(-1).tolist())
    idx = Vt.IntArray.FromNumpy(np.where(jw == 0, 0, ji).reshape(-1).astype(np.int32))
    wts = Vt.FloatArray.FromNumpy(jw.reshape(-1))
    out = []
    for mf, wf in zip(m, W):
        p = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pts))
        sw, bi, si = q.ComputeSubShapeWeights(Vt.FloatArray.FromNumpy(wf.astype(np.float32)))
        assert q.ComputeDeformedPoints(sw, bi, si, indices, offsets, p)
        xf = Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(np.swapaxes(mf, -1, -2)))
        assert UsdSkel.SkinPoints(method, g, xf, idx, wts, ji.shape[1], p)
        out.append(np.asarray(p, dtype=np.float64))
    return np.array(out)


@pytest.mark.parametrize("method", ["classicLinear", "dualQuaternion"])
@pytest.mark.parametrize("seed", range(5))
def test_blend_shapes_then_skinning_match_usdskel_on_every_frame(method, seed):
    """The pre-pass (shapes at weights, in-betweens and extrapolation included) then the one
    kernel equals usd-core's BlendShapeQuery + SkinPoints within 1e-6 x size on random rigs."""
    rng = np.random.default_rng(300 + seed)
    pts, ji, jw, m, G = _dq_rig(rng, n=200, F=6, kind="rigid" if method == "dualQuaternion" else "shear")
    shapes, W = _random_shapes(rng, len(pts), F=6)
    ref = _usd_shaped_skin(pts, ji, jw, m, G, shapes, W, method)
    shaped = SK.shape_points(pts, _kernel_shapes(shapes, len(pts)), W)
    got = SK.skin_frames(shaped, ji, jw, SK.fold_method(method, m, G), dtype=np.float64)
    size = np.linalg.norm(ref.reshape(-1, 3).max(0) - ref.reshape(-1, 3).min(0))
    assert np.abs(got - ref).max() <= 1e-6 * size
    # and the naive reference of the shapes, skinned by the naive LBS
    if method == "classicLinear":
        naive_pts = naive.naive_shape_points(pts, [s[1:] for s in shapes], W)
        np.testing.assert_allclose(shaped, naive_pts, atol=1e-6 * np.abs(naive_pts).max())
        ref2 = np.array([naive.naive_lbs(naive_pts[f], ji, jw, (m @ G)[f:f + 1])[0] for f in range(len(m))])
        assert np.abs(got - ref2).max() <= 1e-6 * size


def test_blend_shapes_part_farthest_per_pose_points():
    """part_farthest on per-pose (shaped) points equals the distances of the skinned shaped points."""
    rng = np.random.default_rng(5)
    pts, ji, jw, m = _random_skin(rng, n=120, F=4)
    shapes, W = _random_shapes(rng, len(pts), F=4)
    shaped = SK.shape_points(pts, _kernel_shapes(shapes, len(pts)), W)
    sk = SK.skin_frames(shaped, ji, jw, m, dtype=np.float64)
    verts = np.arange(0, 120, 3)
    offs = np.array([0, 20, len(verts)])
    centers = rng.normal(size=(4, 2, 3))
    todo = np.ones((4, 2), dtype=bool)
    todo[1, 0] = False
    d, v = SK.part_farthest(shaped, ji, jw, m, offs, verts, centers, todo=todo)
    for f in range(4):
        for p in range(2):
            if not todo[f, p]:
                assert np.isnan(d[f, p]) and v[f, p] == -1
                continue
            vs = verts[offs[p]:offs[p + 1]]
            dist = np.linalg.norm(sk[f, vs] - centers[f, p], axis=1)
            assert d[f, p] == pytest.approx(dist.max(), abs=1e-9)


# -- blend-shape certificate (runtime.certify_shapes) -------------------------------------------
from colossus.runtime import certify_shapes as CS  # noqa: E402


def _skin_naive(method, pts, ji, jw, skin):
    """Naive skinning of per-pose points ``pts`` (F, n, 3) by ``skin`` (F, J, 4, 4)."""
    f = naive.naive_dqs if method == "dualQuaternion" else naive.naive_lbs
    return np.array([f(pts[k], ji, jw, skin[k:k + 1])[0] for k in range(len(skin))])


def random_shape_rig(rng, method="classicLinear", J=5, n=200, F=6, angle=0.3, slack=0.1, S=3):
    """A random rig with blend shapes (in-betweens included) whose weights are animated, skinned
    by ``method``; its spheres fitted to the frames (plus ``slack`` of the radius)."""
    parents, rest_t, rest, bind, pts, ji, jw, order, voff = _random_tree_skin(rng, J, n)
    shapes = []
    for s in range(S):
        idx = np.sort(rng.choice(n, size=n // 2, replace=False))
        off = (0.3 * rng.normal(size=(len(idx), 3))).astype(np.float32)
        ib = [(0.5, (0.3 * rng.normal(size=(len(idx), 3))).astype(np.float32))] if s % 2 else []
        shapes.append((f"s{s}", idx, off, ib))
    ks = _kernel_shapes(shapes, n)
    times = np.arange(F, dtype=float)
    W = rng.uniform(-0.3, 1.3, size=(F, S))
    W[rng.random((F, S)) < 0.2] = 0.0
    q = np.empty((F, J, 4))
    cur = Rotation.random(J, random_state=int(rng.integers(1 << 30)))
    for f in range(F):
        q[f] = cur.as_quat()
        cur = Rotation.from_rotvec(rng.normal(size=(J, 3)) * angle / 2) * cur
    t = rest_t[None] + 0.2 * rng.normal(size=(F, J, 3))
    sc = np.ones((F, J, 3))
    clip = Clip("c", "/c", times, t, times, q.astype(np.float32).astype(float), times, sc, np.arange(J), times,
                tw=times, vw=W.astype(np.float32).astype(float))
    skel = naive.compose(naive.trs(t, clip.vr, sc), parents)
    shaped = SK.shape_points(pts, ks, clip.vw)
    y = _skin_naive(method, shaped, ji, jw, skel @ np.linalg.inv(bind))
    centers, radii = np.zeros((J, 3)), np.zeros(J)
    for p in range(J):
        vs = order[voff[p]:voff[p + 1]]
        loc = np.einsum("fij,fvj->fvi", np.linalg.inv(skel[:, p]),
                        np.concatenate([y[:, vs], np.ones((F, len(vs), 1))], 2))[..., :3]
        lo, hi = loc.reshape(-1, 3).min(0), loc.reshape(-1, 3).max(0)
        centers[p] = (lo + hi) / 2
        radii[p] = np.linalg.norm(loc - centers[p], axis=2).max() * (1 + slack) + 1e-3
    rig = C.Rig(pts, ji, jw, np.eye(4), bind, rest, parents, np.arange(J), centers, radii, voff, order,
                skinning_method=method, shapes=ks)
    return rig, clip, skel


def _dense_shapes(rig, clip, t0, t1, steps=48):
    """(steps - 1, P) joint-space farthest distance of every part at sub-steps of [t0, t1]: joints
    by naive lerp / slerp / T R S, weights by lerp, shapes by naive_shape_points, skin naive."""
    out = []
    shapes = [(rig.shapes.indices[s], rig.shapes.knot_offsets[s][list(rig.shapes.knots[s]).index(1.0)],
               [(k, o) for k, o in zip(rig.shapes.knots[s], rig.shapes.knot_offsets[s]) if k not in (0.0, 1.0)])
              for s in range(len(rig.shapes))]
    for a in np.linspace(0, 1, steps + 1)[1:-1]:
        tt = t0 + a * (t1 - t0)
        i = min(int(np.floor(tt)), len(clip.times) - 2)
        f = tt - i
        skel = naive.compose(naive.trs((1 - f) * clip.vt[i] + f * clip.vt[i + 1],
                                       naive.slerp(clip.vr[i], clip.vr[i + 1], f),
                                       _half_lerp(clip.vs[i], clip.vs[i + 1], f))[None], rig.parents)[0]
        wt = (1 - f) * clip.vw[i] + f * clip.vw[i + 1]
        pts = naive.naive_shape_points(rig.points, shapes, wt[None])
        y = _skin_naive(rig.skinning_method, pts, rig.joint_indices, rig.joint_weights, (skel @ rig.inv_bind)[None])[0]
        far = np.zeros(rig.P)
        for p in range(rig.P):
            vs = rig.verts[rig.vert_offsets[p]:rig.vert_offsets[p + 1]]
            N = skel[rig.part_joint[p]]
            loc = (y[vs] - N[:3, 3]) @ np.linalg.inv(N[:3, :3]).T
            far[p] = np.linalg.norm(loc - rig.part_centers[p], axis=1).max() if len(vs) else 0
        out.append(far)
    return np.array(out)


@pytest.mark.parametrize("seed", range(20))
def test_shape_certificate_is_sound_against_dense_brute_force(seed):
    """20 random blend-shape rigs (linear and dual-quaternion skinning, in-betweens, weights of both
    signs): no certified interval has a dense in-between pose outside a sphere, and the growth
    bound is never below the dense maximum."""
    rng = np.random.default_rng(700 + seed)
    method = "dualQuaternion" if seed % 3 == 2 else "classicLinear"
    rig, clip, skel = random_shape_rig(rng, method, angle=0.2 + 0.05 * (seed % 4), slack=0.05 + 0.05 * (seed % 3))
    s = C.sampled(rig, skel, 0.0, 1e-6, shape_weights=clip.vw)
    ok = ~(s.dist > s.spheres[..., 3] * (1 + 1e-6))
    assert ok[(clip.vw != 0).any(1)].all()  # the spheres were fitted to the shaped frames
    c = CS.certificate(rig, clip, clip.times, s.bound, ok, 0.0, 1e-6)
    g = CS.certificate(rig, clip, clip.times, s.bound, ok, 0.0, 0.0, rho=np.zeros(rig.P), growth=True, max_depth=5)
    certified = (c.status <= 2)
    for i in range(len(clip.times) - 1):
        far = _dense_shapes(rig, clip, clip.times[i], clip.times[i + 1]).max(0)
        assert not (certified[i] & (far > rig.part_radii * (1 + 1e-6))).any(), (i, far, rig.part_radii)
        assert np.all(far <= g.bound[i] * (1 + 1e-9)), (i, far, g.bound[i])
    for f in c.failures:
        if f["definite"]:
            assert f["excess"] > 0
    if method == "classicLinear":  # the bound is not vacuous (DQS: as far as the DQS certificate itself
        assert certified.mean() > 0.3  # goes on these random rotations, hemisphere flips left undecided)


def test_shape_bound_is_tight_enough_that_one_percent_less_is_caught():
    """The dense check has teeth: on some interval the growth bound is within 1% of the dense
    maximum (a bound 1% smaller would fail the soundness test above)."""
    rng = np.random.default_rng(12)
    rig, clip, skel = random_shape_rig(rng, "classicLinear", angle=0.1)
    s = C.sampled(rig, skel, 0.0, 1e-6, shape_weights=clip.vw)
    g = CS.certificate(rig, clip, clip.times, s.bound, np.ones_like(s.bound, bool), 0.0, 0.0,
                       rho=np.zeros(rig.P), growth=True, max_depth=8)
    caught = False
    for i in range(len(clip.times) - 1):
        far = _dense_shapes(rig, clip, clip.times[i], clip.times[i + 1], steps=64).max(0)
        far = np.maximum(far, np.maximum(s.dist[i], s.dist[i + 1]))  # joint = stage space (world = I)
        assert np.all(far <= g.bound[i] * (1 + 1e-6))  # the exact tiers skin float32 points: 6e-8 apart
        caught |= bool(np.any(0.99 * g.bound[i] < far))
    assert caught


def test_vertex_leaving_only_between_samples_by_a_shape_weight_is_caught_with_its_interval():
    """A still skeleton and one shape whose in-between (at weight 0.5) pushes a vertex far out:
    the weight goes 0 -> 1 between the samples, where the vertex is inside; half-way it is out."""
    parents = np.array([-1])
    rest = naive.trs([[0, 0, 0]], [[0, 0, 0, 1.0]], np.ones((1, 3)))
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    ji = np.zeros((4, 1), np.int32)
    jw = np.ones((4, 1), np.float32)
    shapes = [("bulge", np.array([1]), np.array([[0.1, 0, 0]], np.float32),
               [(0.5, np.array([[3.0, 0, 0]], np.float32))])]
    ks = _kernel_shapes(shapes, 4)
    times = np.array([0.0, 1.0])
    clip = Clip("b", "/b", times, np.zeros((2, 1, 3)), times, np.tile([0, 0, 0, 1.0], (2, 1, 1)), times,
                np.ones((2, 1, 3)), np.array([0]), times, tw=times, vw=np.array([[0.0], [1.0]]))
    c = np.zeros(3)
    r = 1.2  # holds every vertex at both samples (1.1 at most), not the bulge (4.0 at w = 0.5)
    rig = C.Rig(pts, ji, jw, np.eye(4), rest, rest, parents, [0], c[None], [r], [0, 4], np.arange(4), shapes=ks)
    skel = naive.compose(naive.trs(clip.vt, clip.vr, clip.vs), parents)
    s = C.sampled(rig, skel, 0.0, 1e-6, shape_weights=clip.vw)
    ok = ~(s.bound > s.spheres[..., 3] * (1 + 1e-6))
    assert ok.all()
    res = CS.certificate(rig, clip, times, s.bound, ok, 0.0, 1e-6)
    assert res.status[0, 0] == 3 and len(res.failures) == 1
    f = res.failures[0]
    assert (f["t0"], f["t1"]) == (0.0, 1.0) and f["definite"] and f["vertex"] == 1
    assert abs(f["time"] - 0.5) <= 0.07 and f["excess"] > 2.0
    # and a plain linear shape (no in-between) with the same ends is certified: its path is a chord
    ks2 = _kernel_shapes([("lin", np.array([1]), np.array([[0.1, 0, 0]], np.float32), [])], 4)
    rig2 = C.Rig(pts, ji, jw, np.eye(4), rest, rest, parents, [0], c[None], [r], [0, 4], np.arange(4), shapes=ks2)
    res2 = CS.certificate(rig2, clip, times, s.bound, ok, 0.0, 1e-6)
    assert res2.status[0, 0] <= 2
