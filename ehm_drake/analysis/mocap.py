"""Motion capture to time series: rigid marker clusters of a C3D session, tracked and
reduced to the project's ``timeseries.csv`` channels.

Frames, in Drake's monogram notation: L the lab (the C3D's coordinates), S the seat frame
(x forward, y left, z up; its axes in the lab from the marker map, ``R_LS``), and for each
rigid cluster a frame C that coincides with L at the cluster's reference pose.  A marker's
reference position ``p_LoQ_L`` is then its position in C, and its position at frame f is
``R_LC(f) p_LoQ_L + p_LoCo_L(f)``.  The pose ``X_LC(f)`` is the least-squares fit of the
reference positions to the visible markers (Kabsch / Soederkvist & Wedin: the SVD of the
cross-covariance, det-corrected), with its RMS residual as the quality figure.

The reference pose of a cluster is its mean pose over the record (the reference posture,
in which the map's origin offsets are given); its shape is that of a frame of typical shape
(marker distances nearest their medians over the record), refined by averaging the markers
brought back through their fitted poses (a rigid template).  A cluster is tracked in every frame
with at least 3 of its markers visible; a frame with fewer is a gap, filled (cubic spline of
the position and the rotation vector) when it is at most ``max_gap_s`` long, an error
otherwise.  Frames at the start or end where a cluster is not tracked are cut off (a warning
says how many).  A residual above ``max_residual_m`` is an error naming the frames and what
is wrong: two markers whose exchanged labels fit (a swap), else the marker off the most.

The channels are those of the simulation (`ehm_drake.systems.outputs.BodyChannels`): a
segment's tracked point M (marker map ``origin``) relative to the seat, on the seat's axes,
plus the seat's own displacement -- the absolute displacement of M from its reference
position, in m -- and the segment's rotation relative to the seat from its reference
orientation, ``R_SB(f) R_SB(ref)^T``, as Drake's roll-pitch-yaw (space-fixed x-y-z,
R = Rz(yaw) Ry(pitch) Rx(roll)), in deg.  The seat acceleration is the accelerometers'
analog channels, ``sign * value / sensitivity``, brought to the point rate by a zero-phase
anti-alias FIR (``scipy.signal.resample_poly``) when the analogs run faster; a seat axis
without an accelerometer is zero (and not an excitation axis).

Every problem raises :class:`~ehm_drake.analysis.formats.DataFormatError` with one line
naming the file, the cluster or marker and the frames; what is repaired (gaps filled,
frames cut) is returned as warnings.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .formats import DIRECTIONS, DataFormatError, TimeSeriesData
from .formats.c3d import C3DSession, read_c3d
from .marker_map import MarkerMap

__all__ = ["MIN_RATE_HZ", "MULTI_AXIS_RATIO", "rigid_fit", "ClusterTrack", "track_cluster",
           "MocapResult", "reduce_session", "read_session", "spans"]

#: Lowest marker rate accepted: 4 samples per period at 12 Hz, the top of the analysis band.
MIN_RATE_HZ = 48.0
#: A seat axis is excited when its RMS is at least this fraction of the largest
#: (`transmissibility`'s own rule).
MULTI_AXIS_RATIO = 0.3
#: Smallest and largest extent of a cluster (m): outside, the units are not what the map says.
CLUSTER_EXTENT_M = (0.005, 1.5)


def rigid_fit(p_ref: np.ndarray, q: np.ndarray, visible: np.ndarray | None = None):
    """Least-squares rigid poses, one per frame (Kabsch via SVD).

    Parameters
    ----------
    p_ref : (n, 3) reference marker positions.
    q : (F, n, 3) measured positions (NaN allowed where not visible).
    visible : (F, n) bool, optional (default: finite ``q``).

    Returns
    -------
    R : (F, 3, 3), p : (F, 3), rms : (F,)
        ``q_k ~ R p_ref_k + p`` over the visible markers; ``rms`` the RMS distance of the
        visible markers from the fit.  NaN in frames with fewer than 3 visible markers.
    """
    q = np.asarray(q, float)
    if visible is None:
        visible = np.isfinite(q).all(axis=2)
    w = visible.astype(float)  # (F, n)
    cnt = w.sum(axis=1)
    ok = cnt >= 3
    qz = np.where(visible[:, :, None], q, 0.0)
    wn = w / np.maximum(cnt, 1.0)[:, None]
    c_p = wn @ p_ref  # (F, 3) centroid of the visible reference markers
    c_q = np.einsum("fn,fni->fi", wn, qz)
    P = p_ref[None] - c_p[:, None]  # (F, n, 3)
    Q = (qz - c_q[:, None]) * w[:, :, None]
    H = np.einsum("fni,fnj->fij", P, Q)  # sum_k P_k Q_k^T
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("fij,fjk->fik", U, Vt)))
    D = np.ones((len(q), 3))
    D[:, 2] = np.where(d == 0, 1.0, d)
    R = np.einsum("fji,fj,fkj->fik", Vt, D, U)  # V diag(D) U^T
    p = c_q - np.einsum("fij,fj->fi", R, c_p)
    err = np.einsum("fij,nj->fni", R, p_ref) + p[:, None] - qz
    rms = np.sqrt((w * np.sum(err**2, axis=2)).sum(axis=1) / np.maximum(cnt, 1.0))
    R[~ok], p[~ok], rms[~ok] = np.nan, np.nan, np.nan
    return R, p, rms


def spans(mask: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in a 1-D mask as (first, last) frame pairs (inclusive)."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(int)))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _frames(runs: list[tuple[int, int]], most: int = 3) -> str:
    text = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs[:most])
    return text + (f" and {len(runs) - most} more" if len(runs) > most else "")


@dataclass
class ClusterTrack:
    """A tracked cluster: reference positions ``p_ref`` (n, 3, lab m), poses ``R_LC``
    (F, 3, 3) and ``p_LoCo_L`` (F, 3), fit residual ``rms`` (F, m; NaN where the pose was
    filled or not tracked), visibility (F, n), and the filled spans."""

    name: str
    markers: tuple[str, ...]
    p_ref: np.ndarray
    R_LC: np.ndarray
    p_LoCo_L: np.ndarray
    rms: np.ndarray
    visible: np.ndarray
    filled: list[tuple[int, int]] = field(default_factory=list)

    @property
    def tracked(self) -> np.ndarray:
        return np.isfinite(self.rms)


def _culprit(markers, p_ref, q, visible, limit) -> str:
    """What makes a cluster's fit bad in frames `q` (F, n, 3): two markers whose labels,
    exchanged, fit within `limit`; else the marker whose leaving out helps the most."""
    q, visible = q[:200], visible[:200]

    def median_rms(qq, vis):
        return float(np.nanmedian(rigid_fit(p_ref, qq, vis)[2]))

    n = len(markers)
    pairs = []
    for i in range(n):
        for j in range(i + 1, n):
            k = np.arange(n)
            k[[i, j]] = k[[j, i]]
            R, _, rms = rigid_fit(p_ref, q[:, k], visible[:, k])
            # A symmetric cluster fits another exchange turned over: of those that fit,
            # the one that keeps the cluster nearest its reference orientation.
            turn = np.nanmedian(np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2,
                                                  -1, 1)))
            pairs.append((float(np.nanmedian(rms)) > limit, turn, float(np.nanmedian(rms)),
                          i, j))
    over, _, r, i, j = min(pairs)
    if not over:
        return (f"markers {markers[i]} and {markers[j]} swapped (their labels exchanged fit "
                f"within {1e3 * r:.2g} mm); fix the labels")
    if n > 3:
        alone = []
        for i in range(n):
            vis = visible.copy()
            vis[:, i] = False
            alone.append((median_rms(q, vis), i))
        r, i = min(alone)
        return (f"marker {markers[i]} off the most (without it {1e3 * r:.2g} mm): a loose, "
                "mislabelled or swapped marker")
    return "a loose, mislabelled or swapped marker"


def _typical_shape(q: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """The cluster's markers in a frame of typical shape: of (up to 400) frames with every
    marker visible, the one whose marker distances are nearest their medians (distances
    do not depend on the pose, and a swap or a loose marker in fewer than half of the
    frames does not move a median); each marker's median position if no frame has all."""
    full = np.flatnonzero(visible.all(axis=1))
    if not full.size:
        return np.nanmedian(np.where(visible[:, :, None], q, np.nan), axis=0)
    pick = full[np.linspace(0, full.size - 1, min(400, full.size)).astype(int)]
    i, j = np.triu_indices(q.shape[1], 1)
    dist = np.linalg.norm(q[pick][:, i] - q[pick][:, j], axis=2)
    return q[pick[np.argmin(np.abs(dist - np.median(dist, axis=0)).sum(axis=1))]].copy()


def track_cluster(name: str, markers: tuple[str, ...], q: np.ndarray, max_residual_m: float,
                  where: str = "", iterations: int = 3) -> ClusterTrack:
    """Reference positions and per-frame poses of one rigid cluster (see the module
    docstring); `q` is (F, n, 3) in m with NaN where a marker is not visible.  Raises
    DataFormatError for a marker never seen, a cluster never tracked, a degenerate or
    implausibly sized cluster, or a residual above `max_residual_m`."""
    visible = np.isfinite(q).all(axis=2)
    never = [m for m, v in zip(markers, visible.any(axis=0), strict=True) if not v]
    if never:
        raise DataFormatError(f"{where}cluster '{name}': marker(s) {never} never visible")
    if not (visible.sum(axis=1) >= 3).any():
        raise DataFormatError(f"{where}cluster '{name}': fewer than 3 of its markers visible "
                              "in every frame")
    p_ref = _typical_shape(q, visible)
    extent = float(np.max(np.linalg.norm(p_ref[:, None] - p_ref[None], axis=2)))
    lo, hi = CLUSTER_EXTENT_M
    if not lo <= extent <= hi:
        raise DataFormatError(
            f"{where}cluster '{name}' spans {extent:.4g} m, outside {lo:g}-{hi:g} m: the "
            "point units are not what the marker map says (units), or markers are mislabelled")
    sv = np.linalg.svd(p_ref - p_ref.mean(axis=0), compute_uv=False)
    if sv[1] < 0.05 * sv[0]:
        raise DataFormatError(f"{where}cluster '{name}': its markers lie nearly on a line; a "
                              "rigid pose needs 3 markers spread in a plane")
    for _ in range(iterations):
        R, p, rms = rigid_fit(p_ref, q, visible)
        good = np.isfinite(rms) & (rms <= max_residual_m)
        if not good.any():
            break
        back = np.einsum("fji,fnj->fni", R[good], q[good] - p[good][:, None])
        vis = visible[good]
        n_vis = vis.sum(axis=0)
        mean = np.where(vis[:, :, None], back, 0.0).sum(axis=0) / np.maximum(n_vis, 1)[:, None]
        p_ref = np.where((n_vis > 0)[:, None], mean, p_ref)
    # The template placed at the cluster's mean pose over the record (the chordal mean of
    # the rotations, projected back onto SO(3)): the reference posture.
    R, p, rms = rigid_fit(p_ref, q, visible)
    good = np.isfinite(rms) & (rms <= max_residual_m)
    if good.any():
        U, _, Vt = np.linalg.svd(R[good].mean(axis=0))
        R_mean = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
        p_ref = p_ref @ R_mean.T + p[good].mean(axis=0)
    R, p, rms = rigid_fit(p_ref, q, visible)
    bad = np.isfinite(rms) & (rms > max_residual_m)
    if bad.any():
        runs = spans(bad)
        raise DataFormatError(
            f"{where}cluster '{name}': fit residual up to {1e3 * np.nanmax(rms[bad]):.3g} mm "
            f"> max_residual_m {1e3 * max_residual_m:g} mm in frames {_frames(runs)} "
            f"({int(bad.sum())} frames): "
            + _culprit(markers, p_ref, q[runs[0][0]:runs[0][1] + 1],
                       visible[runs[0][0]:runs[0][1] + 1], max_residual_m))
    return ClusterTrack(name, markers, p_ref, R, p, rms, visible)


def _fill(track: ClusterTrack, f0: int, f1: int, max_gap: int, rate: float,
          where: str) -> None:
    """Fill the untracked spans inside frames f0..f1 (cubic splines of the position and
    the rotation vector); a span longer than `max_gap` frames raises."""
    from scipy.interpolate import CubicSpline
    from scipy.spatial.transform import Rotation

    inside = np.zeros(len(track.rms), bool)
    inside[f0:f1 + 1] = True
    runs = spans(~track.tracked & inside)
    if not runs:
        return
    long = [(a, b) for a, b in runs if b - a + 1 > max_gap]
    if long:
        a, b = max(long, key=lambda r: r[1] - r[0])
        seen = track.visible[a:b + 1].mean(axis=0)
        lost = [m for m, s in zip(track.markers, seen, strict=True) if s < 0.5]
        raise DataFormatError(
            f"{where}cluster '{track.name}': fewer than 3 markers visible in frames {a}-{b} "
            f"({(b - a + 1) / rate:.3g} s > max_gap_s {max_gap / rate:.3g} s; markers "
            f"{', '.join(lost) or 'in turn'} missing); {len(long)} such gap(s)")
    ok = np.flatnonzero(track.tracked & inside)
    gap = np.concatenate([np.arange(a, b + 1) for a, b in runs])
    track.p_LoCo_L[gap] = CubicSpline(ok, track.p_LoCo_L[ok], axis=0)(gap)
    rv = Rotation.from_matrix(track.R_LC[ok]).as_rotvec()
    track.R_LC[gap] = Rotation.from_rotvec(CubicSpline(ok, rv, axis=0)(gap)).as_matrix()
    track.filled = runs


def _rpy_deg(R: np.ndarray) -> np.ndarray:
    """(F, 3, 3) -> (F, 3) roll, pitch, yaw in deg (`systems.rotations.rpy_from_rotation`)."""
    return np.degrees(np.column_stack([
        np.arctan2(R[:, 2, 1], R[:, 2, 2]),
        np.arctan2(-R[:, 2, 0], np.hypot(R[:, 0, 0], R[:, 1, 0])),
        np.arctan2(R[:, 1, 0], R[:, 0, 0])]))


@dataclass
class MocapResult:
    """A session reduced to the time-series format, with its quality report and the
    warnings (what was repaired)."""

    timeseries: TimeSeriesData
    report: dict
    warnings: list[str]


def _marker_columns(session: C3DSession, mmap: MarkerMap, where: str) -> dict[str, int]:
    """Column of every marker the map names (one error listing all missing ones)."""
    labels = list(session.labels)
    needed = {}
    for c in mmap.clusters.values():
        for m in (*c.markers, *c.origin):
            needed.setdefault(m, c.name)
    missing = [m for m in needed if m not in labels]
    if missing:
        hints = []
        spare = [x for x in labels if x not in needed]  # a misnamed marker is among these
        for m in missing:
            close = difflib.get_close_matches(m, spare, n=1, cutoff=0.6)
            hints.append(f"'{m}' (cluster {needed[m]}" + (f"; the file has '{close[0]}'"
                                                          if close else "") + ")")
        raise DataFormatError(f"{where}marker(s) {', '.join(hints)} not in the file "
                              f"({len(labels)} labels: {', '.join(labels[:12])}"
                              f"{', ...' if len(labels) > 12 else ''})")
    dup = sorted({m for m in needed if labels.count(m) > 1})
    if dup:
        raise DataFormatError(f"{where}marker label(s) {dup} appear more than once")
    return {m: labels.index(m) for m in needed}


def _seat_acceleration(session: C3DSession, mmap: MarkerMap, where: str,
                       warnings: list[str]) -> np.ndarray:
    """(n_frames, 3) seat acceleration on the seat axes (m/s^2), at the point rate."""
    from scipy.signal import resample_poly

    labels = list(session.analog_labels)
    out = np.zeros((session.n_frames, 3))
    for a in mmap.accelerometers:
        if a.channel not in labels:
            close = difflib.get_close_matches(a.channel, labels, n=1, cutoff=0.6)
            raise DataFormatError(
                f"{where}analog channel '{a.channel}' (seat accelerometer, axis {a.axis}) not "
                f"in the file" + (f"; the file has '{close[0]}'" if close else "")
                + f" ({len(labels)} analog channels"
                + (f": {', '.join(labels[:12])})" if labels else ")"))
        j = labels.index(a.channel)
        unit = session.analog_units[j]
        if not unit:
            warnings.append(f"{where}analog channel '{a.channel}' has no unit in the file; "
                            f"taken as the map's {a.unit}")
        elif unit != a.unit:
            raise DataFormatError(f"{where}analog channel '{a.channel}' is in {unit!r} but the "
                                  f"marker map says {a.unit!r} (sensitivity {a.sensitivity:g} "
                                  f"{a.unit} per m/s^2)")
        x = session.analogs[:, j]
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            k = int(bad[0])
            raise DataFormatError(f"{where}analog channel '{a.channel}': non-finite value at "
                                  f"sample {k} (frame {k // max(1, session.analog_ratio)})")
        acc = a.sign * x / a.sensitivity
        r = session.analog_ratio
        if r > 1:
            acc = resample_poly(acc, 1, r, padtype="line")[:session.n_frames]
        out[:, "xyz".index(a.axis)] = acc
    return out


def reduce_session(session: C3DSession, mmap: MarkerMap) -> MocapResult:
    """The time series of one C3D session (see the module docstring).

    The excited axes are the accelerometer axes whose RMS is at least
    `MULTI_AXIS_RATIO` of the largest; ``level_rms`` the largest RMS (m/s^2, 3 significant
    digits).  Raises DataFormatError (one line, naming the file) on any bad input.
    """
    where = f"{session.source}: " if session.source else ""
    warnings: list[str] = []
    rate = session.point_rate
    if rate < MIN_RATE_HZ:
        raise DataFormatError(f"{where}point rate {rate:g} Hz is too low for the 0-12 Hz "
                              f"analysis: at least {MIN_RATE_HZ:g} Hz (4 samples per period "
                              "at 12 Hz)")
    if not session.point_units:
        warnings.append(f"{where}POINT:UNITS not given; taken as the map's {mmap.units}")
    elif session.point_units != mmap.units:
        raise DataFormatError(f"{where}POINT:UNITS is {session.point_units!r} but the marker "
                              f"map{f' ({mmap.source})' if mmap.source else ''} says "
                              f"{mmap.units!r}")
    cols = _marker_columns(session, mmap, where)
    if not len(session.analog_labels):
        raise DataFormatError(f"{where}no analog channels: the seat accelerometer "
                              f"'{mmap.accelerometers[0].channel}' is needed")
    seat_acc = _seat_acceleration(session, mmap, where, warnings)
    xyz = session.points * mmap.scale_m
    tracks = {}
    for name, c in mmap.clusters.items():
        tracks[name] = track_cluster(name, c.markers, xyz[:, [cols[m] for m in c.markers]],
                                     mmap.max_residual_m, where)
    f0 = max(int(np.argmax(t.tracked)) for t in tracks.values())
    f1 = min(len(t.rms) - 1 - int(np.argmax(t.tracked[::-1])) for t in tracks.values())
    if f1 - f0 < 2:
        raise DataFormatError(f"{where}the clusters are never tracked at the same time")
    cut = [f"{a}-{b}" for a, b in ((0, f0 - 1), (f1 + 1, session.n_frames - 1)) if b >= a]
    if cut:
        warnings.append(f"{where}frames {' and '.join(cut)} cut off (a cluster not tracked "
                        "at the start or end)")
    max_gap = int(np.floor(mmap.max_gap_s * rate + 1e-9))
    for t in tracks.values():
        _fill(t, f0, f1, max_gap, rate, where)
    sel = slice(f0, f1 + 1)
    seat = tracks["seat"]
    R_LS = mmap.R_LS
    R_LCs, p_LoCso_L = seat.R_LC[sel], seat.p_LoCo_L[sel]
    p_LoSo_ref = seat.p_ref.mean(axis=0)  # seat origin: the cluster's centre
    # The seat origin's displacement (lab axes).
    d_L = np.einsum("fij,j->fi", R_LCs, p_LoSo_ref) + p_LoCso_L - p_LoSo_ref
    channels = {}
    for name, c in mmap.segments.items():
        t = tracks[name]
        ref = [t.p_ref[c.markers.index(m)] if m in c.markers else
               np.nanmedian(xyz[:, cols[m]], axis=0) for m in c.origin]
        p_LoM_ref = np.mean(ref, axis=0) + R_LS @ np.asarray(c.origin_offset_m)
        p_LoM_L = np.einsum("fij,j->fi", t.R_LC[sel], p_LoM_ref) + t.p_LoCo_L[sel]
        # M relative to the seat (seat frame at its reference pose), plus the seat's own
        # displacement, on the seat axes.
        rel = np.einsum("fji,fj->fi", R_LCs, p_LoM_L - p_LoCso_L)
        disp = (rel - p_LoM_ref + d_L) @ R_LS
        # R_SB(f) R_SB(ref)^T = R_LS^T R_LCs(f)^T R_LCb(f) R_LS.
        R_rel = np.einsum("ji,fkj,fkl,lm->fim", R_LS, R_LCs, t.R_LC[sel], R_LS)
        rpy = _rpy_deg(R_rel)
        for k, dof in enumerate(("x", "y", "z")):
            channels[f"{name}_{dof}"] = disp[:, k]
        for k, dof in enumerate(("roll", "pitch", "yaw")):
            channels[f"{name}_{dof}"] = rpy[:, k]
    acc = seat_acc[sel]
    measured = [a.axis for a in mmap.accelerometers]
    rms = {d: float(np.std(acc[:, DIRECTIONS.index(d)])) for d in measured}
    top = max(rms.values())
    if not top > 0:
        raise DataFormatError(f"{where}the seat accelerometer(s) read a constant: no excitation")
    if not 0.01 <= top <= 20.0:
        warnings.append(f"{where}seat acceleration {top:.3g} m/s^2 RMS is outside 0.01-20 "
                        "m/s^2: check the accelerometer's sensitivity and unit in the map")
    direction = "".join(d for d in DIRECTIONS if d in rms and rms[d] >= MULTI_AXIS_RATIO * top)
    level = float(f"{top:.3g}")
    n = f1 - f0 + 1
    ts = TimeSeriesData(np.arange(n) / rate, acc, channels,
                        {"direction": direction, "level_rms": level},
                        _source=session.source or None)
    report = {"file": Path(session.source).name if session.source else "",
              "point_rate_hz": rate, "analog_rate_hz": session.analog_rate,
              "frames": session.n_frames, "frames_used": [f0, f1], "duration_s": n / rate,
              "direction": direction, "level_rms": level,
              "seat_rms_ms2": {d: rms[d] for d in measured}, "clusters": {}}
    for name, t in tracks.items():
        r = t.rms[sel]
        filled = sum(b - a + 1 for a, b in t.filled)
        report["clusters"][name] = {
            "markers": list(t.markers),
            "residual_median_mm": float(1e3 * np.nanmedian(r)),
            "residual_max_mm": float(1e3 * np.nanmax(r)),
            "marker_missing_frames": {m: int((~t.visible[sel, i]).sum())
                                      for i, m in enumerate(t.markers)},
            "gaps_filled": len(t.filled), "frames_filled": filled,
            "longest_gap_frames": max((b - a + 1 for a, b in t.filled), default=0),
            "filled_spans": [list(s) for s in t.filled[:50]]}
        if t.filled:
            longest = max(t.filled, key=lambda s: s[1] - s[0])
            warnings.append(f"{where}cluster '{name}': {len(t.filled)} gap(s) of fewer than 3 "
                            f"visible markers filled ({filled} frames, longest "
                            f"{longest[0]}-{longest[1]})")
    report["warnings"] = list(warnings)
    return MocapResult(ts, report, warnings)


def read_session(path: str | Path, mmap: MarkerMap) -> MocapResult:
    """`reduce_session` of the C3D file at `path`."""
    return reduce_session(read_c3d(path), mmap)
