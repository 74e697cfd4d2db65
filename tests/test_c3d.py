"""Lab data in C3D: the rigid-cluster fit, the reduction to the simulation's channels, the
marker map, bad input, files written by other software, and the whole lab path (synth
--c3d -> transmissibility --markers -> diagnose) against the direct one."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.signal import butter, sosfiltfilt
from scipy.spatial.transform import Rotation

from ehm_drake.analysis.formats import DataFormatError, TimeSeriesData, read_frf
from ehm_drake.analysis.formats.c3d import read_c3d, write_c3d
from ehm_drake.analysis.lab_c3d import c3d_lab_folder
from ehm_drake.analysis.marker_map import (
    EXAMPLE_MARKER_MAP,
    MarkerMapError,
    load_marker_map,
    marker_map_from_dict,
)
from ehm_drake.analysis.mocap import reduce_session, rigid_fit
from ehm_drake.analysis.transmissibility import transmissibility
from ehm_drake.cli import main
from ehm_drake.gap.lab.synth_c3d import virtual_session
from ehm_drake.realities import CHANNEL_NAMES

SAMPLES = Path(__file__).parent / "data" / "c3d"
ROT = ("roll", "pitch", "yaw")


def _record(seconds=12.0, seed=0, direction="z", fs=200.0) -> TimeSeriesData:
    """A random record: the seat acceleration 0.2-12 Hz on `direction` (0.3 m/s^2 RMS, the
    other axes 0.005), every channel a band of it (a response to the seat: coherence near
    1) plus 5% of its own, 2 mm and 0.5 deg RMS."""
    rng = np.random.default_rng(seed)
    n = int(seconds * fs) + 1

    def band(x, lo, hi, scale):
        y = sosfiltfilt(butter(2, [lo, hi], "bandpass", fs=fs, output="sos"), x)
        return scale * y / y.std()

    acc = 0.005 * rng.standard_normal((n, 3))
    a = band(rng.standard_normal(n), 0.2, 12.0, 0.3)
    acc[:, "xyz".index(direction)] = a
    ch = {}
    for c in CHANNEL_NAMES:
        lo = rng.uniform(0.3, 3.0)
        y = band(a, lo, lo * rng.uniform(2.0, 4.0), 1.0)
        y += band(rng.standard_normal(n), 0.2, 12.0, 0.05)
        ch[c] = (0.5 if c.rsplit("_", 1)[1] in ROT else 0.002) * y / y.std()
    return TimeSeriesData(np.arange(n) / fs, acc, ch, {"direction": direction})


def _rotations(ts, seg):
    rpy = np.column_stack([ts.channels[f"{seg}_{d}"] for d in ROT])
    return Rotation.from_euler("xyz", rpy, degrees=True).as_matrix()  # Rz Ry Rx


@pytest.fixture(scope="module")
def example_map():
    return load_marker_map(EXAMPLE_MARKER_MAP)


# ---------------------------------------------------------------------------
# The rigid fit and the reduction
# ---------------------------------------------------------------------------

def test_a_known_rigid_motion_is_recovered_to_1e_9():
    """Kabsch on 1000 random poses (rotations up to ~90 deg), markers hidden at random:
    every frame with >= 3 visible markers gives R and p to 1e-9, a proper rotation even
    for a planar cluster (where the SVD's reflection must be corrected)."""
    rng = np.random.default_rng(3)
    for p_ref in (rng.normal(size=(5, 3)) * 0.1 + [0.3, 0.1, 0.8],
                  np.array([[0.0, 0, 0], [0.3, 0, 0], [0, 0.2, 0], [0.3, 0.2, 0]])):
        F, n = 1000, len(p_ref)
        R = Rotation.from_rotvec(rng.normal(size=(F, 3)) * 0.8).as_matrix()
        p = rng.normal(size=(F, 3))
        q = np.einsum("fij,nj->fni", R, p_ref) + p[:, None]
        hidden = rng.random((F, n)) < 0.3
        q[hidden] = np.nan
        R_fit, p_fit, rms = rigid_fit(p_ref, q)
        ok = (~hidden).sum(axis=1) >= 3
        assert 0 < (~ok).sum() and ok.sum() > 500
        assert np.abs(R_fit[ok] - R[ok]).max() < 1e-9
        assert np.abs(p_fit[ok] - p[ok]).max() < 1e-9
        assert np.nanmax(rms) < 1e-9
        assert np.allclose(np.linalg.det(R_fit[ok]), 1.0)
        assert np.isnan(rms[~ok]).all() and np.isnan(R_fit[~ok]).all()


def test_a_noise_free_session_gives_back_the_simulation_s_channels(tmp_path, example_map):
    """Markers placed rigidly from a record's channels (no noise; float32 mm in the file; the
    lab turned 90 deg from the seat): the reduction gives each segment's rotation up to a
    constant (its reference is the mean pose, the record's the settled one) to 5e-6 rad, its
    translation up to an offset to 5e-6 m (2 mm RMS), the seat acceleration to float32
    precision.  With 2% marker occlusions and 2% of frames lost, the transmissibility is
    within 0.1% (median) of the record's own."""
    ts = _record(30.0, seed=1)
    for dropout in (0.0, 0.02):
        session = virtual_session(ts, ts.seat_acc, seed=2, noise_m=0.0,
                                  marker_dropout=dropout, frame_dropout=dropout)
        write_c3d(tmp_path / "s.c3d", session)
        res = reduce_session(read_c3d(tmp_path / "s.c3d"), example_map)
        out = res.timeseries
        assert out.meta == {"direction": "z", "level_rms": 0.3}
        assert np.abs(out.seat_acc - ts.seat_acc).max() < 1e-6
        if dropout:
            assert res.report["clusters"]["head"]["gaps_filled"] > 10
            break
        assert res.report["clusters"]["head"]["gaps_filled"] == 0
        for seg in ("pelvis", "trunk", "head", "knee_l", "knee_r"):
            for d in "xyz":
                diff = out.channels[f"{seg}_{d}"] - ts.channels[f"{seg}_{d}"]
                assert np.abs(diff - diff.mean()).max() < 5e-6, (seg, d)
            offset = np.einsum("fji,fjk->fik", _rotations(ts, seg), _rotations(out, seg))
            assert np.abs(offset - offset.mean(axis=0)).max() < 5e-6, seg
    a = transmissibility(ts, "z", nperseg=2000)
    b = transmissibility(out, "z", nperseg=2000)
    sel = (a.coherence > 0.9) & (a.freq_hz >= 0.5)
    assert sel.sum() > 1000
    assert np.median(np.abs(b.gain[sel] / a.gain[sel] - 1)) < 1e-3


def test_the_accelerometer_at_a_multiple_of_the_marker_rate_is_aligned(example_map):
    """Analogs at 5x the marker rate (1 kHz): brought to the frames without delay or gain
    (5 and 11 Hz tones to 0.5%), on the map's seat axis and sign; x excited alone is found
    as the direction, its level to 3 digits."""
    ts = _record(12.0, seed=4, direction="x")
    s = virtual_session(ts, ts.seat_acc, seed=5, noise_m=0.0, marker_dropout=0.0,
                        frame_dropout=0.0)
    t = np.arange(5 * s.n_frames) / 1000.0
    a = 0.3 * np.sin(2 * np.pi * 5 * t + 0.3) + 0.2 * np.sin(2 * np.pi * 11 * t)
    s.analogs = np.column_stack([0.0102 * a, 0 * a, 0 * a])
    s.analog_rate = 1000.0
    out = reduce_session(s, example_map).timeseries
    want = 0.3 * np.sin(2 * np.pi * 5 * ts.t + 0.3) + 0.2 * np.sin(2 * np.pi * 11 * ts.t)
    inner = slice(50, -50)
    assert np.abs(out.seat_acc[inner, 0] - want[inner]).max() < 0.005 * 0.5
    assert np.abs(out.seat_acc[:, 1:]).max() == 0.0
    assert out.meta == {"direction": "x", "level_rms": float(f"{np.std(want):.3g}")}


# ---------------------------------------------------------------------------
# The marker map
# ---------------------------------------------------------------------------

def test_the_example_marker_map_loads_and_is_packaged(example_map):
    m = example_map
    assert EXAMPLE_MARKER_MAP.parent.name == "data"  # ehm_drake/data, package-data *.yaml
    assert m.units == "mm" and m.scale_m == 1e-3
    assert list(m.clusters) == ["seat", "pelvis", "trunk", "head", "knee_l", "knee_r"]
    assert all(len(c.markers) >= 3 for c in m.clusters.values())
    assert m.segments["knee_l"].origin == ("LKNE",)
    np.testing.assert_array_equal(m.R_LS @ [1, 0, 0], [0, -1, 0])  # seat x = lab -Y
    assert [(a.channel, a.axis, a.sign) for a in m.accelerometers] == [
        ("SeatAccX", "x", 1.0), ("SeatAccY", "y", 1.0), ("SeatAccZ", "z", 1.0)]


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["clusters"]["head"].update(markers=["LFHD", "RFHD"]),
     r"clusters\.head\.markers: needs at least 3 markers \(a rigid pose\), got 2"),
    (lambda d: d.update(seat_axes={"x": "+X", "y": "+Y", "z": "-Z"}),
     r"seat_axes: .* is not a right-handed frame"),
    (lambda d: d["clusters"]["trunk"]["markers"].append("LFHD"),
     r"clusters\.head\.markers: marker 'LFHD' is also in cluster 'trunk'"),
    (lambda d: d.update(max_gap=0.1), r"marker map: unknown key\(s\) \['max_gap'\]"),
    (lambda d: d["clusters"].update(neck={"markers": ["A", "B", "C"]}),
     r"clusters: unknown cluster\(s\) \['neck'\]"),
    (lambda d: d["accelerometers"][0].update(sensitivity=-1),
     r"accelerometers\[0\]\.sensitivity: = -1: allowed 0 < value"),
    (lambda d: d.update(units="inch"), r"units: must be one of mm, cm, m, got 'inch'"),
])
def test_a_bad_marker_map_is_refused_naming_the_key(tmp_path, edit, message):
    d = yaml.safe_load(EXAMPLE_MARKER_MAP.read_text())
    edit(d)
    path = tmp_path / "map.yaml"
    path.write_text(yaml.safe_dump(d))
    with pytest.raises(MarkerMapError, match=f"^{tmp_path / 'map.yaml'}: {message}") as e:
        load_marker_map(path)
    assert "\n" not in str(e.value)


def test_a_marker_map_that_is_not_yaml_names_the_line(tmp_path):
    path = tmp_path / "map.yaml"
    path.write_text("units: mm\nclusters: {seat: [A, B\n")
    with pytest.raises(MarkerMapError, match=r"map\.yaml: line 3: not valid YAML"):
        load_marker_map(path)


# ---------------------------------------------------------------------------
# Bad input: one line naming the file, the marker or cluster and the frames
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def good_session():
    ts = _record(12.0, seed=7)
    return virtual_session(ts, ts.seat_acc, seed=8, marker_dropout=0.0, frame_dropout=0.0)


def _labels(s, rename):
    s.labels = tuple(rename.get(x, x) for x in s.labels)


def _swap(s, a, b, frame):
    i, j = s.labels.index(a), s.labels.index(b)
    s.points[frame:, [i, j]] = s.points[frame:, [j, i]]


def _hide(s, names, frames):
    for m in names:
        s.points[frames, s.labels.index(m)] = np.nan


@pytest.mark.parametrize("edit, message", [
    (lambda s: _labels(s, {"LASI": "L_ASI", "RBHD": "X1"}),
     r"marker\(s\) 'LASI' \(cluster pelvis; the file has 'L_ASI'\), 'RBHD' \(cluster head\) "
     r"not in the file \(26 labels: SEAT_FL"),
    (lambda s: _hide(s, ["LFHD", "RBHD"], slice(1000, 1101)),
     r"cluster 'head': fewer than 3 markers visible in frames 1000-1100 \(0\.505 s > "
     r"max_gap_s 0\.05 s; markers LFHD, RBHD missing\); 1 such gap"),
    (lambda s: _hide(s, ["LTH1", "LTH2"], slice(None)),
     r"cluster 'knee_l': marker\(s\) \['LTH1', 'LTH2'\] never visible"),
    (lambda s: _swap(s, "LFHD", "RBHD", 1500),
     r"cluster 'head': fit residual up to \d+(\.\d+)? mm > max_residual_m 3 mm in frames "
     r"1500-2400 \(901 frames\): markers LFHD and RBHD swapped \(their labels exchanged fit "
     r"within 0\.\d+ mm\); fix the labels$"),
    (lambda s: setattr(s, "point_units", "m"),
     r"POINT:UNITS is 'm' but the marker map \(.*marker_map_example\.yaml\) says 'mm'"),
    (lambda s: setattr(s, "points", s.points / 1000.0),
     r"cluster 'seat' spans 0\.00\d+ m, outside 0\.005-1\.5 m: the point units are not "
     r"what the marker map says"),
    (lambda s: setattr(s, "analog_units", ("V", "V", "mV")),
     r"analog channel 'SeatAccZ' is in 'mV' but the marker map says 'V'"),
    (lambda s: setattr(s, "analog_labels", ("SeatAccX", "SeatAccY", "Seat_Acc_Z")),
     r"analog channel 'SeatAccZ' \(seat accelerometer, axis z\) not in the file; the file "
     r"has 'Seat_Acc_Z'"),
])
def test_bad_sessions_are_refused_in_one_line(tmp_path, example_map, good_session, edit,
                                              message):
    import copy

    s = copy.deepcopy(good_session)
    edit(s)
    path = tmp_path / "session.c3d"
    write_c3d(path, s)
    with pytest.raises(DataFormatError, match=f"^{path}: {message}") as e:
        reduce_session(read_c3d(path), example_map)
    assert "\n" not in str(e.value)


def test_a_bad_file_among_several_leaves_nothing_written(tmp_path, example_map, good_session,
                                                         capsys):
    """Two sessions, the second with a swap: no lab folder; the CLI exits 2 with one line
    naming the file, and keeps an existing folder without --force."""
    import copy

    write_c3d(tmp_path / "a.c3d", good_session)
    bad = copy.deepcopy(good_session)
    _swap(bad, "STRN", "CLAV", 100)
    write_c3d(tmp_path / "b.c3d", bad)
    out = tmp_path / "lab"
    with pytest.raises(DataFormatError, match=r"b\.c3d: cluster 'trunk'"):
        c3d_lab_folder([tmp_path / "a.c3d", tmp_path / "b.c3d"], example_map, out,
                       progress=False)
    assert not out.exists()
    assert main(["transmissibility", str(tmp_path / "a.c3d"), str(tmp_path / "b.c3d"),
                 "--markers", str(EXAMPLE_MARKER_MAP), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "b.c3d: cluster 'trunk': fit residual" in err[0]
    assert not out.exists()
    assert main(["transmissibility", str(tmp_path / "a.c3d"), "--out", str(out)]) == 2
    assert "need --markers MAP.yaml" in capsys.readouterr().err


# ---------------------------------------------------------------------------
# Files written by other software
# ---------------------------------------------------------------------------

def test_c3d_files_from_other_software_are_read(tmp_path):
    """An Optotrak and a Qualisys file (tests/data/c3d/README.md): labels, rates, units,
    invalid samples (negative residuals) as NaN, analogs at 4x the marker rate; written
    back and read again unchanged (float32); the 30 Hz Optotrak session is refused for
    the 0-12 Hz analysis, naming its rate."""
    s = read_c3d(SAMPLES / "Optotrak.c3d")
    assert (s.point_rate, s.point_units, s.points.shape) == (30.0, "mm", (29, 54, 3))
    assert s.labels[:2] == ("Marker_1", "Marker_2") and len(set(s.labels)) == 54
    assert int(np.isnan(s.points[..., 0]).sum()) == 59 and s.analog_ratio == 0
    q = read_c3d(SAMPLES / "FP_Type3.c3d")
    assert (q.point_rate, q.analog_rate, q.analog_ratio) == (250.0, 1000.0, 4)
    assert q.points.shape == (2, 34, 3) and q.analogs.shape == (8, 16)
    assert q.labels[:4] == ("LPSIS", "RPSIS", "LASIS", "RASIS") and q.analog_units[0] == "N"
    assert np.isfinite(q.points).all() and 100 < np.abs(q.points).max() < 5000
    for session in (s, q):
        write_c3d(tmp_path / "copy.c3d", session)
        again = read_c3d(tmp_path / "copy.c3d")
        assert again.labels == session.labels
        np.testing.assert_array_equal(np.isnan(again.points), np.isnan(session.points))
        np.testing.assert_allclose(again.points, session.points, rtol=1e-6)
        np.testing.assert_allclose(again.analogs, session.analogs, rtol=1e-5, atol=1e-5)
    m = marker_map_from_dict({"units": "mm", "accelerometers": [
        {"channel": "A", "axis": "z", "unit": "V", "sensitivity": 1.0}],
        "clusters": {"seat": {"markers": ["Marker_1", "Marker_2", "Marker_3"]},
                     "head": {"markers": ["Marker_4", "Marker_5", "Marker_6"]}}})
    with pytest.raises(DataFormatError, match=r"Optotrak\.c3d: point rate 30 Hz is too low "
                                              r"for the 0-12 Hz analysis: at least 48 Hz"):
        reduce_session(s, m)


# ---------------------------------------------------------------------------
# The whole lab path against the direct one
# ---------------------------------------------------------------------------

def test_a_simulation_written_as_c3d_gives_its_direct_transmissibility(tmp_path, capsys):
    """The acceptance round trip: `synth --c3d` (60 s vertical, implicit design), read back
    by `transmissibility --markers`: within 2% (median over the bins with coherence > 0.9 in
    both, 0.5-12 Hz) of the same run's direct frf.csv, with 0.15 mm marker noise, 2% of
    frames dropped and 2% marker occlusions (1.65% for this seed; 1.5-1.7% over five).  Both
    estimates carry their own measurement noise (each 1.3-1.4%, median, from the noise-free
    record's at 60 s): on 30 s records they differ by about 3%, over the bar."""
    data, lab = tmp_path / "data", tmp_path / "lab"
    assert main(["synth", "--effect", "none", "--seed", "5", "--directions", "z", "--levels",
                 "0.3", "--duration", "60", "--design", "implicit", "--c3d", "--workers", "1",
                 "--out", str(data), "--key", str(tmp_path / "key.json"), "--quiet"]) == 0
    c3d = data / "c3d"
    assert sorted(p.name for p in c3d.iterdir()) == ["marker_map.yaml", "z_0.3.c3d"]
    s = read_c3d(c3d / "z_0.3.c3d")
    lost = np.isnan(s.points[..., 0]).all(axis=1).mean()
    assert 0.015 < lost < 0.025
    assert 0.03 < np.isnan(s.points[..., 0]).mean() < 0.05
    assert main(["transmissibility", str(c3d / "z_0.3.c3d"), "--markers",
                 str(c3d / "marker_map.yaml"), "--out", str(lab), "--quiet"]) == 0
    printed = capsys.readouterr()
    assert "z_0.3.c3d: z @ 0.3 m/s^2, 60.0 s at 200 Hz" in printed.out
    assert "cluster 'head':" in printed.err and "filled" in printed.err
    direct, c3d_frf = read_frf(data / "frf.csv"), read_frf(lab / "frf.csv")
    assert len(direct) == len(c3d_frf)
    assert (direct.segment == c3d_frf.segment).all() and (direct.dof == c3d_frf.dof).all()
    np.testing.assert_allclose(direct.freq_hz, c3d_frf.freq_hz, rtol=1e-9)
    sel = ((direct.coherence > 0.9) & (c3d_frf.coherence > 0.9) & (direct.freq_hz >= 0.5)
           & (direct.freq_hz <= 12.0))
    err = np.abs(c3d_frf.gain[sel] / direct.gain[sel] - 1)
    assert sel.sum() > 450
    assert np.median(err) < 0.02, np.median(err)
    report = json.loads((lab / "mocap_report.json").read_text())["sessions"][0]
    assert report["frames_used"] == [0, s.n_frames - 1]
    for c in report["clusters"].values():
        assert 0.1 < c["residual_median_mm"] < 0.25 and c["longest_gap_frames"] <= 10
    tests = json.loads((lab / "tests.json").read_text())["tests"]
    assert tests == [{"direction": "z", "level_rms": 0.3, "timeseries": "z_0.3/timeseries.csv",
                      "duration_s": tests[0]["duration_s"],
                      "n_averages": int(direct.n_averages[0]),
                      "c3d": "z_0.3.c3d"}]


@pytest.mark.slow
def test_diagnose_gives_the_same_verdict_on_the_c3d_made_lab_folder(tmp_path):
    """`blind --c3d` on the short blind protocol's foam trial (vertical, 0.3 and 0.6 m/s^2,
    60 s; the three candidates of tests/test_gap_blind.py; data and model on the implicit
    design, as `blind --design implicit`): diagnose runs on the lab folder
    made from the C3D sessions alone and names the foam; diagnose on the same trial's
    direct frf.csv (the synthetic lab's own folder) gives the same verdict and effect."""
    from test_gap_blind import CANDIDATES, SHORT_BLIND

    from ehm_drake.diagram import on_design
    from ehm_drake.gap.lab.blind import BlindSpec, run_blind
    from ehm_drake.params import load_params

    # 60 s records: the C3D path's marker noise and the direct path's own
    # estimate differ by about 3% on 30 s records (see the round trip), enough
    # to put a foam at 0.71 of its range on either side of the diagnosis' bar.
    # (The implicit design's data are three times faster to make; the C3D path,
    # not the design, is under test.)
    params = on_design(load_params(), "implicit")
    spec = BlindSpec(**dict(SHORT_BLIND, trials=1, p_none=0.0, duration_s=60.0), workers=2,
                     c3d=True, params=params.to_dict())
    s = run_blind(spec, tmp_path, progress=False)
    trial = tmp_path / "trial_000"
    tests = json.loads((trial / "data" / "tests.json").read_text())["tests"]
    assert [t["c3d"] for t in tests] == ["z_0.3.c3d", "z_0.6.c3d"]
    assert (trial / "data_lab" / "c3d" / "z_0.6.c3d").is_file()
    via_c3d = json.loads((trial / "diagnosis" / "report.json").read_text())
    assert main(["diagnose", str(trial / "data_lab"), "--out", str(tmp_path / "direct"),
                 "--params", str(tmp_path / "params.json"), "--quiet", "--workers", "2",
                 "--effects", ",".join(CANDIDATES)]) == 0
    direct = json.loads((tmp_path / "direct" / "report.json").read_text())
    assert (via_c3d["verdict"], via_c3d["best_effect"]) == \
        (direct["verdict"], direct["best_effect"]) == ("explained", "seat_foam_stiffening")
    assert s["top1"] == 1.0, s["confusion"]
    shutil.rmtree(tmp_path / "direct")
