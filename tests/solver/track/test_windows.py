"""Sliding windows of tracking (solver.track.windows): the schedule and the bit-identical fixed frame
(T19), the joint update's gradient against central differences of its energy, the temporal term skipped
at w_temp = 0 (T13), and on the tube body in a smooth motion with noisy partial captures: windows after
per-frame fits lower the error and the jitter."""
import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.solver.errors import ArticulaInputError
from articula.solver.geometry.rotations import quat_to_rotvec, rotvec_to_quat
from articula.solver.rig.model import Poses
from articula.solver.rig.skinning import AnchorGroups, hybrid_skin
from articula.solver.track import frame_fit as ff
from articula.solver.track import temporal, windows
from articula.solver.tracking.pose_prior import PosePrior
from articula.solver.geometry.normals import vertex_normals


def test_schedule_of_the_dissertation():
    """T19: [0..10], [5..15], [10..20], ... (half-open here), the last clipped; every frame covered and
    consecutive windows sharing size − step frames."""
    assert windows.window_schedule(23) == [(0, 11), (5, 16), (10, 21), (15, 23)]
    assert windows.window_schedule(21) == [(0, 11), (5, 16), (10, 21)]
    assert windows.window_schedule(11) == [(0, 11)] and windows.window_schedule(4) == [(0, 4)]
    assert windows.window_schedule(12) == [(0, 11), (5, 12)] and windows.window_schedule(0) == []
    s = windows.window_schedule(100, 7, 3)
    assert s[0][0] == 0 and s[-1][1] == 100 and all(b - a == 7 for a, b in s[:-1])
    assert all(a2 == a1 + 3 for (a1, _), (a2, _) in zip(s, s[1:]))
    for args in ((10, 11, 11), (10, 11, 0), (10, 1, 1), (-1, 11, 5), (10.0, 11, 5)):
        with pytest.raises(ArticulaInputError, match="window schedule"):
            windows.window_schedule(*args)


def _motion(model, n, seed=0):
    """A smooth motion: every joint's rotation vector a slow sinusoid, the root walking along x."""
    rng = np.random.default_rng(seed)
    B = model.skeleton.num_bones
    t = np.arange(n)[:, None, None]
    r = rng.normal(size=(B, 3)) * 0.25 * np.sin(0.15 * t + rng.uniform(0, 2 * np.pi, (B, 3)))
    r[:, 0] *= 0.3
    return Poses(rotvec_to_quat(r), np.stack([0.01 * np.arange(n), np.zeros(n), np.zeros(n)], axis=1), np.ones(n))


def _captures(model, truth, rng, noise, keep=0.6):
    """Per frame a random ``keep`` share of the posed vertices with their normals, Gaussian noise."""
    out = []
    for posed in hybrid_skin(model, truth):
        k = rng.random(len(posed)) < keep
        out.append(ff.Capture(posed[k] + rng.normal(scale=noise, size=(k.sum(), 3)),
                              vertex_normals(posed, model.faces)[k]))
    return out


@pytest.fixture(scope="module")
def small():
    model = synthetic.tube_body(rings=6, segments=6)
    truth = _motion(model, 4)
    return model, truth, _captures(model, truth, np.random.default_rng(1), 0.003)


def _jittered(truth, rng, deg=4.0):
    r = quat_to_rotvec(truth.rotations) + np.deg2rad(deg) * rng.normal(size=truth.rotations.shape[:2] + (3,))
    return Poses(rotvec_to_quat(r), truth.translations + 0.005 * rng.normal(size=truth.translations.shape),
                 truth.scales.copy())


def test_window_gradient_matches_its_energy_and_the_system_is_block_pentadiagonal(small):
    """The joint update's gradient (data, pose prior with bounded bones in exp-map coordinates, temporal
    rows) is half the central difference of its energy along random directions over the four free frames
    and along each coordinate of one frame; H couples a frame with the two before and after it only
    (a second difference spans three frames), and not at all with w_temp = 0."""
    model, truth, caps = small
    rng = np.random.default_rng(2)
    sk = model.skeleton
    prior = PosePrior.from_poses(sk, synthetic.random_poses(12, sk.num_bones, seed=5, max_angle=0.5), k_max=1,
                                 margin=1.0)
    start = _jittered(truth, rng)
    frames = [windows._frame(start, n) for n in range(4)]
    groups = AnchorGroups(model)
    options = ff.FrameFitOptions(w_pose=0.01)
    pairs = [ff._refresh(model, groups, frames[n], caps[n], options) for n in range(4)]
    win = windows._Window(model, groups, frames, range(4), pairs, prior, 0.5, options)
    assert all(u.bounded[1:].all() for u in win.updates)
    win.build(None)
    h = 1e-6
    P = len(win.rows[0])
    directions = np.concatenate([rng.normal(size=(24, 4 * P)), np.eye(4 * P)[2 * P:3 * P]])
    fd = np.array([(win.try_steps(None, h * d[None])[0] - win.try_steps(None, -h * d[None])[0]) / (2 * h)
                   for d in directions])
    assert np.allclose(fd, 2 * directions @ win.g, rtol=1e-5, atol=1e-6 * np.abs(win.g).max())
    blocks = np.abs(win.H).reshape(4, P, 4, P).max(axis=(1, 3))
    assert (blocks[[0, 1, 2, 0, 1], [1, 2, 3, 2, 3]] > 0).all() and blocks[0, 3] == 0
    flat = windows._Window(model, groups, frames, range(4), pairs, prior, 0.0, options)
    flat.build(None)
    blocks = np.abs(flat.H).reshape(4, P, 4, P).max(axis=(1, 3))
    assert (blocks[~np.eye(4, dtype=bool)] == 0).all()


def test_fixed_frame_is_bit_identical_and_w_temp_zero_never_evaluates_the_term(small, monkeypatch):
    """T19: frame 0's arrays come back bit for bit (even a quaternion normalised only to 1e-9); T13:
    with w_temp = 0 the temporal term is never evaluated."""
    model, truth, caps = small
    start = _jittered(truth, np.random.default_rng(3))
    start.rotations[0, 2] *= 1.0 + 1e-9
    fixed = [start.rotations[0].tobytes(), start.translations[0].tobytes(), start.scales[0].tobytes()]
    out, log = windows.fit_window(model, caps, start, True, None, 1.0, max_updates=2)
    assert [out.rotations[0].tobytes(), out.translations[0].tobytes(), out.scales[0].tobytes()] == fixed
    assert not np.array_equal(out.rotations[1:], start.rotations[1:]) and log["updates"] == 2
    assert log["temp"][-1] < log["temp"][0] and log["Q"].min() < log["Q"][0]

    def refuse(*args, **kwargs):
        raise AssertionError("temporal term evaluated with w_temp = 0")
    for name in ("value", "residuals", "jacobian"):
        monkeypatch.setattr(temporal, name, refuse)
    out, log = windows.fit_window(model, caps, start, True, None, 0.0, max_updates=1)
    assert (log["temp"] == 0).all() and out.rotations[0].tobytes() == fixed[0]


def test_windows_over_a_sequence_keep_each_start_frame_and_bad_input_is_refused(small, monkeypatch):
    """fit_windows: every window after the first holds its first frame bit for bit (the previous window's
    result); the first only with fix_start; a frame without data is listed and still moves (temporal
    term); the input poses are not modified."""
    model, truth, caps = small
    start = _jittered(truth, np.random.default_rng(4))
    before = start.rotations.copy()
    seen, original = [], windows.fit_window

    def spy(model_, captures, init, fix_first, *args):
        out, log = original(model_, captures, init, fix_first, *args)
        seen.append((fix_first, init.rotations[0].tobytes(), out.rotations[0].tobytes()))
        return out, log
    monkeypatch.setattr(windows, "fit_window", spy)
    source = list(caps[:3]) + [None]
    reports = []
    out, logs = windows.fit_windows(model, source, start, None, 1.0, size=3, step=1, max_updates=1,
                                    progress=lambda f, text: reports.append(f))
    assert reports == sorted(reports) and reports[-1] == 1.0 and len(reports) == 4
    assert [(lg["start"], lg["stop"]) for lg in logs] == [(0, 3), (1, 4)]
    assert [s[0] for s in seen] == [False, True] and seen[1][1] == seen[1][2]
    assert logs[1]["no_data"] == [2] and not np.array_equal(out.rotations[3], start.rotations[3])
    assert np.array_equal(start.rotations, before)
    windows.fit_windows(model, source, start, None, 1.0, size=3, step=1, max_updates=1, fix_start=True)
    assert seen[2][0] and seen[2][1] == seen[2][2]
    for call, msg in ((lambda: windows.fit_windows(model, caps[:3], start), "4 poses for 3"),
                      (lambda: original(model, caps, start, True, None, -1.0), "w_temp"),
                      (lambda: original(model, caps[:3], start, True), "3 captures for 4")):
        with pytest.raises(ArticulaInputError, match=msg):
            call()


def _second_difference(poses):
    r = quat_to_rotvec(poses.rotations[:, 1:])
    return np.linalg.norm(r[2:] - 2 * r[1:-1] + r[:-2], axis=2).mean()


def test_windows_reduce_jitter_of_per_frame_fits():
    """Tube body in a smooth motion, 60 % of the vertices per frame with 5 mm noise: the per-frame fits
    (pass 1, each from the previous result) jitter (the tubes' twist is barely observable); one window
    with w_temp from the heuristic of Eq. 4.16 keeps frame 0 and lowers both the mean vertex error against
    the truth and the mean second difference of the joints' rotation vectors."""
    model = synthetic.tube_body(rings=8, segments=8)
    n = 6
    truth = _motion(model, n, seed=0)
    caps = _captures(model, truth, np.random.default_rng(0), 0.005)
    groups = AnchorGroups(model)
    options = ff.FrameFitOptions(max_iterations=12)
    pose, fits = windows._frame(truth, 0), []
    for cap in caps:
        fits.append(ff.fit_frame(model, cap, pose, None, options, groups))
        pose = fits[-1].pose
    pass1 = Poses(*(np.concatenate([getattr(f.pose, k) for f in fits]) for k in ("rotations", "translations",
                                                                                  "scales")))
    w = temporal.temporal_weight([f.log["data"].min() for f in fits], pass1.rotations)
    out, log = windows.fit_window(model, caps, pass1, True, None, w, options, groups, max_updates=8)
    posed = hybrid_skin(model, truth)

    def error(p):
        return np.linalg.norm(hybrid_skin(model, p) - posed, axis=2).mean()
    print(f"w_temp {w:.3g}; error {error(pass1) * 1e3:.2f} -> {error(out) * 1e3:.2f} mm, second difference "
          f"{_second_difference(pass1):.4f} -> {_second_difference(out):.4f} rad (truth "
          f"{_second_difference(truth):.4f}), {log['updates']} updates")
    assert np.isfinite(w) and w > 0
    assert error(out) < error(pass1)
    assert _second_difference(out) < 0.5 * _second_difference(pass1)
    assert np.array_equal(out.rotations[0], pass1.rotations[0])
