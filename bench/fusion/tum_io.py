"""Reading/writing the TUM RGB-D benchmark layout, poses and trajectory metrics.

Layout of a dataset folder:
    rgb/  depth/           images (depth: 16-bit PNG, metres = value / depth_scale, 0 = missing)
    rgb.txt  depth.txt     lines "timestamp path" ('#' comments)
    groundtruth.txt        lines "timestamp tx ty tz qx qy qz qw" (camera-to-world;
                           camera looks +z, x right, y down)
    scene.ply              (synthetic sequences only) true scene mesh, world frame
Pure numpy; no Open3D import here.
"""
import os
import sys

import numpy as np

TUM_INTRINSICS = dict(width=640, height=480, fx=525.0, fy=525.0, cx=319.5, cy=239.5)
TUM_DEPTH_SCALE = 5000.0


class DatasetError(Exception):
    pass


def fail(msg, code=2):
    print(f"error: {msg}", file=sys.stderr)
    sys.exit(code)


def read_file_list(path):
    """Return a sorted list of (timestamp, [fields...]) from a TUM list file."""
    if not os.path.isfile(path):
        raise DatasetError(f"missing file: {path}")
    out = []
    with open(path) as f:
        for lineno, line in enumerate(f, 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            parts = line.replace(",", " ").split()
            try:
                out.append((float(parts[0]), parts[1:]))
            except (ValueError, IndexError):
                raise DatasetError(f"{path}:{lineno}: cannot parse line: {line!r}")
    out.sort(key=lambda x: x[0])
    return out


def associate(first, second, max_dt=0.02):
    """TUM associate.py: greedy unique matching of two timestamp lists by |dt| <= max_dt.

    first/second: sorted lists of timestamps. Returns list of (i, j) index pairs sorted by i.
    """
    a = np.asarray(first, dtype=np.float64)
    b = np.asarray(second, dtype=np.float64)
    if len(a) == 0 or len(b) == 0:
        return []
    cand = []
    # for each a, only neighbours in b within max_dt (b sorted)
    lo = np.searchsorted(b, a - max_dt, side="left")
    hi = np.searchsorted(b, a + max_dt, side="right")
    for i in range(len(a)):
        for j in range(lo[i], hi[i]):
            cand.append((abs(a[i] - b[j]), i, j))
    cand.sort()
    used_a, used_b, pairs = set(), set(), []
    for _, i, j in cand:
        if i in used_a or j in used_b:
            continue
        used_a.add(i)
        used_b.add(j)
        pairs.append((i, j))
    pairs.sort()
    return pairs


# ---------------------------------------------------------------- rotations

def quat_to_rot(q):
    """q = (qx, qy, qz, qw) -> 3x3 rotation matrix."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def rot_to_quat(R):
    """3x3 rotation -> (qx, qy, qz, qw) with qw >= 0."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        w, x, y, z = 0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        w, x, y, z = (R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] > R[2, 2]:
        s = np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        w, x, y, z = (R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s
    else:
        s = np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        w, x, y, z = (R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s
    q = np.array([x, y, z, w])
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


def pose_matrix(t, q):
    T = np.eye(4)
    T[:3, :3] = quat_to_rot(q)
    T[:3, 3] = t
    return T


def slerp(q0, q1, a):
    q0 = np.asarray(q0, float)
    q1 = np.asarray(q1, float)
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + a * (q1 - q0)
        return q / np.linalg.norm(q)
    th = np.arccos(d)
    return (np.sin((1 - a) * th) * q0 + np.sin(a * th) * q1) / np.sin(th)


def interpolate_pose(gt_t, gt_tq, t, max_dt):
    """Camera-to-world 4x4 at time t: linear/slerp between the bracketing ground-truth
    samples, or the nearest sample if t is outside (within max_dt). None if no sample
    is within max_dt of t."""
    i = int(np.searchsorted(gt_t, t))
    if i < len(gt_t) and abs(gt_t[i] - t) < 1e-9:
        return pose_matrix(gt_tq[i, :3], gt_tq[i, 3:])
    if 0 < i < len(gt_t):
        t0, t1 = gt_t[i - 1], gt_t[i]
        if min(t - t0, t1 - t) > max_dt:
            return None
        a = (t - t0) / (t1 - t0)
        tr = (1 - a) * gt_tq[i - 1, :3] + a * gt_tq[i, :3]
        q = slerp(gt_tq[i - 1, 3:], gt_tq[i, 3:], a)
        return pose_matrix(tr, q)
    j = 0 if i == 0 else len(gt_t) - 1
    if abs(gt_t[j] - t) > max_dt:
        return None
    return pose_matrix(gt_tq[j, :3], gt_tq[j, 3:])


# ---------------------------------------------------------------- dataset

def load_sequence(root, max_dt=0.02, need_gt=True):
    """Return list of dicts {timestamp, depth, rgb, pose(4x4 cam-to-world or None)}.

    Pairs depth with rgb by TUM association (|dt| <= max_dt); pose from groundtruth.txt
    interpolated at the depth timestamp. Frames without a pose are dropped if need_gt.
    """
    if not os.path.isdir(root):
        raise DatasetError(f"dataset folder not found: {root}")
    depth_list = read_file_list(os.path.join(root, "depth.txt"))
    rgb_list = read_file_list(os.path.join(root, "rgb.txt"))
    if not depth_list:
        raise DatasetError(f"{root}/depth.txt lists no frames")
    pairs = associate([d[0] for d in depth_list], [r[0] for r in rgb_list], max_dt)
    if not pairs:
        raise DatasetError("no depth/rgb pairs within max_dt; check timestamps")
    gt_path = os.path.join(root, "groundtruth.txt")
    gt_t = gt_tq = None
    if os.path.isfile(gt_path):
        gt = read_file_list(gt_path)
        gt_t = np.array([g[0] for g in gt])
        try:
            gt_tq = np.array([[float(v) for v in g[1][:7]] for g in gt])
        except ValueError as e:
            raise DatasetError(f"{gt_path}: {e}")
        if gt_tq.ndim != 2 or gt_tq.shape[1] != 7:
            raise DatasetError(f"{gt_path}: expected 'timestamp tx ty tz qx qy qz qw'")
    elif need_gt:
        raise DatasetError(f"missing file: {gt_path}")
    frames, dropped = [], 0
    for i, j in pairs:
        ts = depth_list[i][0]
        pose = interpolate_pose(gt_t, gt_tq, ts, max_dt) if gt_t is not None else None
        if pose is None and need_gt:
            dropped += 1
            continue
        frames.append(dict(
            timestamp=ts,
            depth=os.path.join(root, depth_list[i][1][0]),
            rgb=os.path.join(root, rgb_list[j][1][0]),
            pose=pose,
        ))
    if not frames:
        raise DatasetError("no frames with ground-truth pose")
    for fr in frames[:1]:
        for k in ("depth", "rgb"):
            if not os.path.isfile(fr[k]):
                raise DatasetError(f"missing image: {fr[k]}")
    return frames, dropped


def intrinsic_matrix(fx, fy, cx, cy):
    return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)


def write_tum_trajectory(path, timestamps, poses):
    with open(path, "w") as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n")
        for ts, T in zip(timestamps, poses):
            q = rot_to_quat(T[:3, :3])
            f.write("%.6f %.6f %.6f %.6f %.6f %.6f %.6f %.6f\n" % (ts, *T[:3, 3], *q))


# ---------------------------------------------------------------- ATE

def align_horn(est, gt):
    """Rigid (no scale) least-squares alignment gt ~ R @ est + t (Horn/Umeyama).
    est, gt: (N,3). Returns R (3x3), t (3,)."""
    mu_e, mu_g = est.mean(0), gt.mean(0)
    E, G = est - mu_e, gt - mu_g
    U, _, Vt = np.linalg.svd(G.T @ E)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1
    R = U @ S @ Vt
    t = mu_g - R @ mu_e
    return R, t


def ate(est_positions, gt_positions):
    """TUM absolute trajectory error: align (rigid, no scale), RMS of position differences."""
    est = np.asarray(est_positions, float)
    gt = np.asarray(gt_positions, float)
    R, t = align_horn(est, gt)
    err = np.linalg.norm((est @ R.T + t) - gt, axis=1)
    return dict(
        rmse_m=float(np.sqrt(np.mean(err ** 2))),
        mean_m=float(err.mean()),
        median_m=float(np.median(err)),
        max_m=float(err.max()),
        count=int(len(err)),
        unaligned_rmse_m=float(np.sqrt(np.mean(np.sum((est - gt) ** 2, axis=1)))),
    )
