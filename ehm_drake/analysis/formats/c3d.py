"""C3D motion-capture files: :class:`C3DSession`, :func:`read_c3d` and :func:`write_c3d`.

A C3D file (https://www.c3d.org) holds labelled 3D marker trajectories sampled at the point
rate and analog channels (force plates, EMG, accelerometers) sampled at a whole multiple of
it, with their units in the parameter section (``POINT:UNITS``, ``ANALOG:UNITS``).  The file
is read and written with `ezc3d <https://github.com/pyomeca/ezc3d>`_, which handles the
processor formats (Intel, DEC, MIPS), integer and float storage and the analog scaling
(``ANALOG:SCALE``, ``GEN_SCALE``, ``OFFSET``: the analogs below are in their units).

A marker's sample is invalid (occluded, not reconstructed) where its residual is negative;
ezc3d returns NaN coordinates there, and :func:`write_c3d` writes NaN coordinates with the
residual -1, so other software reads them as gaps too.

Errors raise :class:`~ehm_drake.analysis.formats.DataFormatError` naming the file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .common import DataFormatError

__all__ = ["C3DSession", "read_c3d", "write_c3d"]


@dataclass(eq=False)
class C3DSession:
    """The marker trajectories and analog channels of one C3D file, in the file's units.

    Attributes
    ----------
    point_rate : float
        Marker sample rate (Hz).
    point_units : str
        ``POINT:UNITS`` (``"mm"``, ``"m"``...); ``""`` when the file does not say.
    labels : tuple of str
        Marker labels (``POINT:LABELS``, stripped).
    points : numpy.ndarray, shape (n_frames, n_markers, 3)
        Marker positions in ``point_units``; NaN where a marker is not visible.
    analog_rate : float
        Analog sample rate (Hz), a whole multiple of the point rate (0 without analogs).
    analog_labels, analog_units : tuple of str
        Per analog channel (``ANALOG:LABELS``, ``ANALOG:UNITS``; ``""`` where not given).
    analogs : numpy.ndarray, shape (n_frames * analog_ratio, n_channels)
        Analog samples in their units (scaling and offset applied).
    source : str
        The file (for messages).
    """

    point_rate: float
    point_units: str
    labels: tuple[str, ...]
    points: np.ndarray
    analog_rate: float = 0.0
    analog_labels: tuple[str, ...] = ()
    analog_units: tuple[str, ...] = ()
    analogs: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    source: str = ""

    def __post_init__(self) -> None:
        self.points = np.asarray(self.points, dtype=np.float64)
        self.analogs = np.asarray(self.analogs, dtype=np.float64).reshape(-1, len(
            self.analog_labels)) if len(self.analog_labels) else np.zeros((0, 0))
        where = f"{self.source}: " if self.source else ""
        if self.points.ndim != 3 or self.points.shape[1:] != (len(self.labels), 3):
            raise DataFormatError(f"{where}points must have shape (frames, {len(self.labels)}, "
                                  f"3), got {self.points.shape}")
        if not (np.isfinite(self.point_rate) and self.point_rate > 0):
            raise DataFormatError(f"{where}POINT:RATE must be positive, got {self.point_rate}")
        if len(self.analog_units) != len(self.analog_labels):
            raise DataFormatError(f"{where}{len(self.analog_labels)} analog labels but "
                                  f"{len(self.analog_units)} units")

    @property
    def n_frames(self) -> int:
        return int(self.points.shape[0])

    @property
    def analog_ratio(self) -> int:
        """Analog samples per marker frame (0 without analogs)."""
        if not len(self.analog_labels) or self.analog_rate <= 0:
            return 0
        return int(round(self.analog_rate / self.point_rate))


def _param(group: dict, name: str, default=None):
    entry = group.get(name)
    if not isinstance(entry, dict) or "value" not in entry:
        return default
    return entry["value"]


def _strings(value, n: int) -> tuple[str, ...]:
    """A C3D string list of length n ('' where missing; one string for all)."""
    if value is None:
        return ("",) * n
    items = [str(v).strip() for v in (value if isinstance(value, list | tuple) else [value])]
    if len(items) == 1 and n > 1:
        items = items * n
    return tuple((items + [""] * n)[:n])


def read_c3d(path: str | Path) -> C3DSession:
    """Read a C3D file.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    DataFormatError
        If it is not a readable C3D file, or its point or analog section is inconsistent.
    """
    import ezc3d

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"C3D file not found: {path}")
    try:
        c = ezc3d.c3d(str(path))
    except (RuntimeError, ValueError, OSError, IndexError) as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DataFormatError(f"{path}: not a readable C3D file ({msg})") from None
    params = c["parameters"]
    point, analog = params.get("POINT", {}), params.get("ANALOG", {})
    pts = np.asarray(c["data"]["points"], dtype=np.float64)  # (4, markers, frames)
    n_markers = pts.shape[1] if pts.ndim == 3 else 0
    labels = _strings(_param(point, "LABELS"), n_markers)
    rate = _param(point, "RATE", [0.0])
    rate = float(rate[0]) if len(rate) else 0.0
    units = {u for u in _strings(_param(point, "UNITS"), max(n_markers, 1)) if u}
    if len(units) > 1:
        raise DataFormatError(f"{path}: POINT:UNITS mixes {sorted(units)}")
    points = np.transpose(pts[:3], (2, 1, 0)) if n_markers else np.zeros((pts.shape[-1], 0, 3))
    res = c["data"].get("meta_points", {}).get("residuals")
    if res is not None and np.size(res) and n_markers:
        points = points.copy()
        points[np.transpose(np.asarray(res)[0]) < 0] = np.nan
    an = np.asarray(c["data"]["analogs"], dtype=np.float64)  # (1, channels, samples)
    n_ch = an.shape[1] if an.ndim == 3 else 0
    a_rate = _param(analog, "RATE", [0.0])
    a_rate = float(a_rate[0]) if len(a_rate) else 0.0
    session = C3DSession(
        point_rate=rate, point_units=next(iter(units), ""), labels=labels, points=points,
        analog_rate=a_rate if n_ch else 0.0, analog_labels=_strings(_param(analog, "LABELS"),
                                                                     n_ch),
        analog_units=_strings(_param(analog, "UNITS"), n_ch),
        analogs=an[0].T if n_ch else np.zeros((0, 0)), source=str(path))
    if n_ch:
        ratio = a_rate / rate if rate > 0 else 0.0
        if ratio < 1 or abs(ratio - round(ratio)) > 1e-6:
            raise DataFormatError(f"{path}: ANALOG:RATE {a_rate:g} Hz is not a whole multiple "
                                  f"of POINT:RATE {rate:g} Hz")
    return session


def write_c3d(path: str | Path, session: C3DSession) -> Path:
    """Write `session` as a C3D file (float storage, Intel format): NaN marker samples get
    the residual -1 (invalid), analogs their labels and units with unit scale."""
    import ezc3d

    path = Path(path)
    s = session
    ratio = s.analog_ratio
    if len(s.analog_labels) and s.analogs.shape[0] != ratio * s.n_frames:
        raise DataFormatError(f"{path}: {s.analogs.shape[0]} analog samples for {s.n_frames} "
                              f"frames at {ratio} per frame")
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(s.point_rate)]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(s.labels)
    c.add_parameter("POINT", "UNITS", s.point_units)
    pts = np.ones((4, len(s.labels), s.n_frames))
    invalid = np.isnan(s.points).any(axis=2).T  # (markers, frames)
    pts[:3] = np.transpose(np.nan_to_num(s.points, nan=0.0), (2, 1, 0))
    pts[:3, invalid] = np.nan
    c["data"]["points"] = pts
    res = np.where(invalid, -1.0, 0.0)[None]
    c["data"]["meta_points"] = {"residuals": res,
                                "camera_masks": np.zeros((7, len(s.labels), s.n_frames), bool)}
    if len(s.analog_labels):
        c["parameters"]["ANALOG"]["RATE"]["value"] = [float(s.analog_rate)]
        c["parameters"]["ANALOG"]["LABELS"]["value"] = tuple(s.analog_labels)
        c["parameters"]["ANALOG"]["UNITS"]["value"] = tuple(s.analog_units)
        c["data"]["analogs"] = s.analogs.T[None]
    c.write(str(path))
    return path
