"""Tests for ehm_drake.analysis.formats (file formats, validation, unit checks)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ehm_drake.analysis.formats import (
    DataFormatError,
    FrfData,
    TimeSeriesData,
    check_units,
    parse_channel_name,
    read_data_dir,
    read_frf,
    read_timeseries,
)

# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------


def make_frf(level: float | None = 0.5, scale_trans: float = 1.0, scale_rot: float = 1.0):
    """Plausible FRF table: z excitation, pelvis_z (m/m) and head_pitch (deg/m)."""
    f = np.round(np.arange(0.25, 12.01, 0.25), 6)
    wn, z = 2 * np.pi * 5.0, 0.3
    s = 2j * np.pi * f
    h = (wn**2 + 2 * z * wn * s) / (s**2 + 2 * z * wn * s + wn**2)
    rot = 25.0 * np.abs(h)  # deg/m: head pitch ~0.4-0.9 rad/m, a realistic magnitude
    rows = []
    for seg, dof, g, ph, sc in (
        ("pelvis", "z", np.abs(h), np.degrees(np.angle(h)), scale_trans),
        ("head", "pitch", rot, np.degrees(np.angle(h)) + 90.0, scale_rot),
    ):
        for i in range(f.size):
            row = {
                "direction": "z",
                "segment": seg,
                "dof": dof,
                "freq_hz": float(f[i]),
                "gain": float(g[i] * sc),
                "phase_deg": float(ph[i]),
                "coherence": float(0.9 + 0.1 * np.cos(f[i]) ** 2),
            }
            if level is not None:
                row["level_rms"] = level
            rows.append(row)
    return FrfData.from_rows(rows)


def make_ts(fs: float = 50.0, duration: float = 12.0, meta: dict | None = None) -> TimeSeriesData:
    n = int(round(fs * duration))
    t = np.arange(n) / fs
    rng = np.random.default_rng(1)
    acc = rng.standard_normal((n, 3)) * [0.1, 0.1, 1.0]
    return TimeSeriesData(
        t=t,
        seat_acc=acc,
        channels={
            "pelvis_z": 1e-3 * np.sin(2 * np.pi * 2 * t),
            "head_pitch": 0.3 * np.cos(2 * np.pi * 3 * t),
            "knee_l_z": 1e-4 * t,
        },
        meta=meta or {},
    )


FRF_HEADER = "direction,segment,dof,freq_hz,gain,phase_deg,coherence"
GOOD_ROW = "z,head,pitch,1.0,20.0,-10.0,0.9"


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------------------------------
# FRF
# ------------------------------------------------------------------------------------------


def test_frf_round_trip_is_exact(tmp_path):
    frf = make_frf(level=0.5)
    path = frf.to_csv(tmp_path / "frf.csv")
    assert path.read_text().splitlines()[0] == FRF_HEADER + ",level_rms"
    back = read_frf(path)
    for col in ("freq_hz", "gain", "phase_deg", "coherence", "level_rms"):
        np.testing.assert_array_equal(getattr(back, col), getattr(frf, col))  # bit-exact
    for col in ("direction", "segment", "dof"):
        assert list(getattr(back, col)) == list(getattr(frf, col))
    assert back.channels() == [("z", "pelvis", "z", 0.5), ("z", "head", "pitch", 0.5)]


def test_frf_without_level_round_trip(tmp_path):
    frf = make_frf(level=None)
    assert not frf.has_level and np.all(np.isnan(frf.level_rms))
    path = frf.to_csv(tmp_path / "frf.csv")
    assert path.read_text().splitlines()[0] == FRF_HEADER  # no level column written
    back = read_frf(path)
    assert np.all(np.isnan(back.level_rms))
    assert back.channels() == [("z", "pelvis", "z"), ("z", "head", "pitch")]


def test_frf_empty_level_cell_is_nan(tmp_path):
    path = write(
        tmp_path / "frf.csv",
        f"{FRF_HEADER},level_rms\n{GOOD_ROW},\nz,head,pitch,2.0,20.0,-10.0,0.9,0.4\n",
    )
    frf = read_frf(path)
    assert np.isnan(frf.level_rms[0]) and frf.level_rms[1] == 0.4
    assert frf.channels() == [("z", "head", "pitch", None), ("z", "head", "pitch", 0.4)]


def test_frf_select_and_get():
    a = make_frf(level=0.5)
    b = make_frf(level=1.0)
    frf = FrfData.concat([a, b])
    assert len(frf.channels()) == 4
    sub = frf.select(segment="head", level=1.0)
    assert len(sub) == len(a) // 2
    assert set(sub.dof) == {"pitch"} and np.all(sub.level_rms == 1.0)
    assert np.all(np.diff(sub.freq_hz) > 0)
    f, g, ph, coh = frf.get("z", "pelvis", "z", level=0.5)
    np.testing.assert_array_equal(g, a.select(segment="pelvis").gain)
    with pytest.raises(DataFormatError, match="2 channels match"):
        frf.get("z", "pelvis", "z")
    with pytest.raises(DataFormatError, match="no FRF rows"):
        frf.get("x", "pelvis", "z")
    with pytest.raises(DataFormatError, match="unknown segment 'neck'"):
        frf.select(segment="neck")


def test_frf_concat_detects_duplicates():
    a = make_frf(level=0.5)
    with pytest.raises(DataFormatError, match="duplicate of row 0"):
        FrfData.concat([a, a])


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        (f"{FRF_HEADER}\nz,neck,pitch,1.0,20.0,-10.0,0.9\n", r"line 2, column 'segment'.*'neck'"),
        (
            f"{FRF_HEADER}\n{GOOD_ROW}\nz,head,tilt,1.0,20.0,-10.0,0.9\n",
            r"line 3, column 'dof'.*'tilt'",
        ),
        (f"{FRF_HEADER}\nw,head,pitch,1.0,20.0,-10.0,0.9\n", r"line 2, column 'direction'"),
        (f"{FRF_HEADER},comment\n{GOOD_ROW},hi\n", r"line 1: unknown column.*'comment'"),
        (
            "direction,segment,dof,freq_hz,gain,coherence\nz,head,pitch,1,2,0.5\n",
            r"missing column.*'phase_deg'",
        ),
        (
            f"{FRF_HEADER}\n{GOOD_ROW}\nz,head,pitch,2.0,nan,-10.0,0.9\n",
            r"line 3, column 'gain': non-finite",
        ),
        (f"{FRF_HEADER}\nz,head,pitch,2.0,1.0,inf,0.9\n", r"line 2, column 'phase_deg': non-fin"),
        (
            f"{FRF_HEADER}\nz,head,pitch,abc,1.0,0.0,0.9\n",
            r"line 2, column 'freq_hz': 'abc' is not a number",
        ),
        (f"{FRF_HEADER}\nz,head,pitch,1.0,,0.0,0.9\n", r"line 2, column 'gain': empty value"),
        (f"{FRF_HEADER}\nz,head,pitch,1.0,-0.5,0.0,0.9\n", r"line 2, column 'gain'.*>= 0"),
        (
            f"{FRF_HEADER}\n{GOOD_ROW}\nz,head,pitch,2.0,1.0,0.0,1.2\n",
            r"line 3, column 'coherence'.*\[0, 1\]",
        ),
        (f"{FRF_HEADER}\nz,head,pitch,0.0,1.0,0.0,0.5\n", r"line 2, column 'freq_hz'.*> 0"),
        (f"{FRF_HEADER},level_rms\n{GOOD_ROW},-1\n", r"line 2, column 'level_rms'.*> 0"),
        (f"{FRF_HEADER}\n{GOOD_ROW}\n{GOOD_ROW}\n", r"line 3: duplicate of line 2"),
        (f"{FRF_HEADER}\nz,head,pitch,1.0,1.0\n", r"line 2: has 5 fields but the header has 7"),
        (f"{FRF_HEADER}\n", r"no data rows"),
        ("", r"file is empty"),
    ],
)
def test_frf_bad_input_names_culprit(tmp_path, text, pattern):
    path = write(tmp_path / "frf.csv", text)
    with pytest.raises(DataFormatError, match=pattern) as info:
        read_frf(path)
    assert "frf.csv" in str(info.value)


def test_frf_from_rows_errors_name_row():
    rows = [
        {
            "direction": "z",
            "segment": "head",
            "dof": "z",
            "freq_hz": 1.0,
            "gain": 1.0,
            "phase_deg": 0.0,
            "coherence": 0.9,
        },
        {
            "direction": "z",
            "segment": "head",
            "dof": "z",
            "freq_hz": 2.0,
            "gain": 1.0,
            "phase_deg": 0.0,
            "coherence": -0.1,
        },
    ]
    with pytest.raises(DataFormatError, match=r"row 1, column 'coherence'"):
        FrfData.from_rows(rows)
    with pytest.raises(DataFormatError, match=r"row 0: unknown column.*'gain_db'"):
        FrfData.from_rows([{**rows[0], "gain_db": 0.0}])
    with pytest.raises(DataFormatError, match=r"row 0: missing column.*'gain'"):
        FrfData.from_rows([{k: v for k, v in rows[0].items() if k != "gain"}])


# ------------------------------------------------------------------------------------------
# unit checks
# ------------------------------------------------------------------------------------------


def test_check_units_clean_data_has_no_warning():
    assert check_units(make_frf()) == []


def test_check_units_flags_mm_translational():
    msgs = check_units(make_frf(scale_trans=1000.0))
    assert len(msgs) == 1 and "pelvis_z" in msgs[0] and "mm" in msgs[0]
    msgs = check_units(make_frf(scale_trans=1e-3))
    assert len(msgs) == 1 and "pelvis_z" in msgs[0] and "< 0.02" in msgs[0]


def test_check_units_flags_rotation_in_rad():
    msgs = check_units(make_frf(scale_rot=np.pi / 180))  # deg/m -> rad/m
    assert len(msgs) == 1 and "rad/m" in msgs[0]
    msgs = check_units(make_frf(scale_rot=1000.0))
    assert len(msgs) == 1 and "head_pitch" in msgs[0] and "mm" in msgs[0]


def test_check_units_flags_phase_in_radians():
    frf = make_frf()
    frf_rad = FrfData(
        frf.direction,
        frf.segment,
        frf.dof,
        frf.freq_hz,
        frf.gain,
        np.radians(frf.phase_deg),
        frf.coherence,
        frf.level_rms,
    )
    msgs = check_units(frf_rad)
    assert len(msgs) == 1 and "radians" in msgs[0]


# ------------------------------------------------------------------------------------------
# time series
# ------------------------------------------------------------------------------------------


def test_parse_channel_name():
    assert parse_channel_name("knee_l_z") == ("knee_l", "z")
    assert parse_channel_name("head_pitch") == ("head", "pitch")
    assert parse_channel_name("trunk_yaw") == ("trunk", "yaw")
    for bad in ("neck_pitch", "head_tilt", "head", "knee_z", "_z"):
        with pytest.raises(DataFormatError, match=f"unknown channel name '{bad}'"):
            parse_channel_name(bad)


def test_timeseries_round_trip_header_meta(tmp_path):
    ts = make_ts(meta={"level_rms": 0.3, "direction": "z"})
    path = ts.to_csv(tmp_path / "timeseries.csv")
    first = path.read_text().splitlines()[0]
    assert first.startswith("# ") and json.loads(first[2:]) == {"level_rms": 0.3, "direction": "z"}
    back = read_timeseries(path)
    np.testing.assert_array_equal(back.t, ts.t)
    np.testing.assert_array_equal(back.seat_acc, ts.seat_acc)
    assert list(back.channels) == ["pelvis_z", "head_pitch", "knee_l_z"]
    for k, v in ts.channels.items():
        np.testing.assert_array_equal(back.channels[k], v)
    assert back.meta == {"level_rms": 0.3, "direction": "z"}
    assert back.excited_directions == ("z",)
    assert back.fs == pytest.approx(50.0, rel=1e-12)
    assert back.n_samples == 600 and back.duration == pytest.approx(12.0)
    np.testing.assert_array_equal(back.seat("z"), ts.seat_acc[:, 2])


def test_timeseries_sidecar_meta(tmp_path):
    ts = make_ts(meta={"level_rms": 0.8, "direction": ["z", "x"]})
    assert ts.meta["direction"] == "xz"  # normalised to canonical axis order
    path = ts.to_csv(tmp_path / "timeseries.csv", meta="sidecar")
    assert not path.read_text().startswith("#")
    assert json.loads((tmp_path / "meta.json").read_text()) == {"level_rms": 0.8, "direction": "xz"}
    back = read_timeseries(path)
    assert back.meta == {"level_rms": 0.8, "direction": "xz"}
    assert back.excited_directions == ("x", "z")


def test_timeseries_conflicting_meta(tmp_path):
    path = make_ts(meta={"level_rms": 0.3}).to_csv(tmp_path / "timeseries.csv")
    write(tmp_path / "meta.json", json.dumps({"level_rms": 0.5, "direction": "z"}))
    with pytest.raises(DataFormatError, match="'level_rms' is 0.3 in the comment header but 0.5"):
        read_timeseries(path)
    write(tmp_path / "meta.json", json.dumps({"level_rms": 0.3, "direction": "z"}))
    assert read_timeseries(path).meta == {"level_rms": 0.3, "direction": "z"}  # merged


def _ts_text(n: int = 600, fs: float = 50.0, extra: str = "", header_extra: str = "") -> list[str]:
    lines = [f"t,seat_ax,seat_ay,seat_az,head_z{header_extra}"]
    for i in range(n):
        lines.append(f"{i / fs!r},0.1,0.2,{np.sin(i / 7):.6f},{1e-3 * np.cos(i / 5):.6f}{extra}")
    return lines


def test_timeseries_bad_values_name_line_and_column(tmp_path):
    lines = _ts_text()
    lines[11] = lines[11].replace(",0.2,", ",nan,", 1)
    path = write(tmp_path / "timeseries.csv", "\n".join(lines) + "\n")
    with pytest.raises(DataFormatError, match=r"line 12, column 'seat_ay': non-finite"):
        read_timeseries(path)
    lines = _ts_text()
    lines[5] = lines[5].replace(",0.1,", ",x1,", 1)
    write(path, "\n".join(lines) + "\n")
    with pytest.raises(DataFormatError, match=r"line 6, column 'seat_ax': 'x1' is not a number"):
        read_timeseries(path)


def test_timeseries_missing_seat_and_unknown_columns(tmp_path):
    lines = ["t,seat_ax,seat_az,head_z"] + [f"{i / 50},0,0,0" for i in range(600)]
    path = write(tmp_path / "timeseries.csv", "\n".join(lines))
    with pytest.raises(DataFormatError, match=r"missing seat acceleration column.*'seat_ay'"):
        read_timeseries(path)
    lines = _ts_text(extra=",1.0", header_extra=",neck_pitch")
    write(path, "\n".join(lines))
    with pytest.raises(DataFormatError, match=r"line 1, column 'neck_pitch': unknown column"):
        read_timeseries(path)
    lines = ["seat_ax,seat_ay,seat_az"] + ["0,0,0"] * 600
    write(path, "\n".join(lines))
    with pytest.raises(DataFormatError, match=r"missing time column 't'"):
        read_timeseries(path)


def test_timeseries_sampling_errors(tmp_path):
    lines = _ts_text()
    lines[101] = (
        lines[101].split(",", 1)[0].replace("2.0", "1.98") + "," + lines[101].split(",", 1)[1]
    )
    path = write(tmp_path / "timeseries.csv", "\n".join(lines))
    with pytest.raises(DataFormatError, match=r"line 102, column 't': time is not increasing"):
        read_timeseries(path)
    t = np.arange(600) / 50.0
    t[300:] += 0.001  # one step 5 % longer than the others
    with pytest.raises(DataFormatError, match=r"row 300, column 't': non-uniform sampling"):
        TimeSeriesData(t=t, seat_acc=np.zeros((600, 3)))
    # jitter below the 1e-3 relative tolerance is accepted
    t = np.arange(600) / 50.0 + 1e-6 * np.sin(np.arange(600))
    assert TimeSeriesData(t=t, seat_acc=np.zeros((600, 3))).fs == pytest.approx(50.0, rel=1e-4)


def test_timeseries_too_short_says_which(tmp_path):
    path = make_ts(fs=100.0, duration=5.0).to_csv(tmp_path / "timeseries.csv")
    with pytest.raises(DataFormatError, match=r"5 s, less than the minimum 10 s"):
        read_timeseries(path)
    path = make_ts(fs=20.0, duration=12.0).to_csv(tmp_path / "timeseries.csv")
    with pytest.raises(DataFormatError, match=r"240 samples, fewer than the minimum 256"):
        read_timeseries(path)
    assert read_timeseries(path, min_samples=200).n_samples == 240


def test_timeseries_bad_meta(tmp_path):
    lines = ['# {"level_rms": 0.3, direction: z}'] + _ts_text()
    path = write(tmp_path / "timeseries.csv", "\n".join(lines))
    with pytest.raises(DataFormatError, match=r"line 1: comment header is not valid JSON"):
        read_timeseries(path)
    lines = ['# {"level_rms": 0.3, "direction": "w"}'] + _ts_text()
    write(path, "\n".join(lines))
    with pytest.raises(DataFormatError, match=r"metadata 'direction'='w'"):
        read_timeseries(path)
    lines = ['# {"level_rms": -2}'] + _ts_text()
    write(path, "\n".join(lines))
    with pytest.raises(DataFormatError, match=r"metadata 'level_rms' must be a finite positive"):
        read_timeseries(path)


def test_timeseries_constructor_shape_errors():
    t = np.arange(10) / 10
    with pytest.raises(DataFormatError, match=r"shape \(10, 3\)"):
        TimeSeriesData(t=t, seat_acc=np.zeros((10, 2)))
    with pytest.raises(DataFormatError, match=r"column 'head_z': channel has shape"):
        TimeSeriesData(t=t, seat_acc=np.zeros((10, 3)), channels={"head_z": np.zeros(9)})
    with pytest.raises(DataFormatError, match=r"unknown channel name 'head_tilt'"):
        TimeSeriesData(t=t, seat_acc=np.zeros((10, 3)), channels={"head_tilt": np.zeros(10)})


def test_timeseries_from_columns():
    ts = make_ts(meta={"direction": "z", "level_rms": 1.0})
    names = ["t", "seat_ax", "seat_ay", "seat_az", *ts.channels]
    data = np.column_stack([ts.t, ts.seat_acc, *ts.channels.values()])
    back = TimeSeriesData.from_columns(names[::-1], data[:, ::-1], meta=ts.meta)  # any order
    np.testing.assert_array_equal(back.seat_acc, ts.seat_acc)
    np.testing.assert_array_equal(back.channels["head_pitch"], ts.channels["head_pitch"])
    assert back.meta == {"direction": "z", "level_rms": 1.0} and back.fs == pytest.approx(50)
    with pytest.raises(DataFormatError, match=r"missing seat acceleration column.*'seat_az'"):
        TimeSeriesData.from_columns(names[:3], data[:, :3])
    with pytest.raises(DataFormatError, match=r"column 'pelvis_tilt': unknown column"):
        TimeSeriesData.from_columns([*names[:4], "pelvis_tilt"], data[:, :5])
    with pytest.raises(DataFormatError, match=r"shape \(N, 7\)"):
        TimeSeriesData.from_columns(names, data[:, :6])
    with pytest.raises(DataFormatError, match=r"duplicate column\(s\) \['head_pitch'\]"):
        TimeSeriesData.from_columns([*names[:6], "head_pitch"], data)


def test_read_data_dir(tmp_path):
    with pytest.raises(FileNotFoundError, match="neither frf.csv nor timeseries.csv"):
        read_data_dir(tmp_path)
    with pytest.raises(FileNotFoundError, match="not found"):
        read_data_dir(tmp_path / "missing")
    make_frf().to_csv(tmp_path / "frf.csv")
    frf, ts = read_data_dir(tmp_path)
    assert frf is not None and ts is None and len(frf) == 96
    make_ts(meta={"direction": "z"}).to_csv(tmp_path / "timeseries.csv")
    frf, ts = read_data_dir(tmp_path)
    assert frf is not None and ts is not None and ts.meta == {"direction": "z"}
