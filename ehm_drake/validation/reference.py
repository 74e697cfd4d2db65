"""Measured reference datasets a lab supplies, compared frequency by
frequency with the model (`ehm-drake validate --reference FILE`).

Format: a YAML or JSON file, one dataset per file::

    quantity: apparent_mass          # or: transmissibility
    direction: z                     # the seat excitation axis
    segment: head                    # transmissibility only: pelvis, trunk, head,
    dof: z                           #   knee_l, knee_r; dof x, y, z, roll, pitch, yaw
    configuration: rigid_seat        # the model's configuration (see `ehm-drake
                                     #   validate --help`): car_seat, rigid_seat, ...
    level_rms: 1.0                   # m/s^2 r.m.s. of the tests
    band_hz: [0.5, 20.0]             # optional: the random excitation's band
    provenance:                      # all required (free text): where it comes from
      citation: "Author A, Author B. Title. Journal 1(2):3-4, 2020"
      posture: "upright, hands in lap"
      seat: "rigid flat seat, no backrest"
      subjects: "12 men, 20-40 years"
      level: "1.0 m/s^2 r.m.s., random 0.5-20 Hz"
      obtained: "median of the subjects, measured in our lab"  # or digitized from Fig. N
      doi: "10.xxxx/yyyy"            # optional
    data:
      freq_hz: [...]                 # > 0, increasing
      mean: [...]                    # normalized apparent mass (-), or m/m / deg/m
      lower: [...]                   # the range (e.g. interquartile, or mean -+ sd)
      upper: [...]
      phase_deg: [...]               # optional

Every list has the length of ``freq_hz``; ``lower <= mean <= upper``; no
NaN.  A bad or incomplete file is refused with one line naming the file and
the field (`ReferenceError`).

The comparison (`compare`): the model's curve interpolated at the
dataset's frequencies (within the model's analysis band, 0.5-12 Hz); the
share of those frequencies where it lies inside [lower, upper]; the peak
frequency and peak modulus of the model against the dataset's mean (their
errors); the phase's RMS difference where given.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

PROVENANCE_FIELDS = ("citation", "posture", "seat", "subjects", "level", "obtained")
QUANTITIES = ("apparent_mass", "transmissibility")
SEGMENTS = ("pelvis", "trunk", "head", "knee_l", "knee_r")
DOFS = ("x", "y", "z", "roll", "pitch", "yaw")
#: Frequencies compared (Hz): the model's analysis band above the Welch
#: estimate's first bins.
COMPARE_BAND_HZ = (0.5, 12.0)


class ReferenceError(ValueError):
    """A reference dataset file is invalid; the message names the file and field."""


@dataclass
class ReferenceDataset:
    path: Path
    quantity: str
    direction: str
    segment: str
    dof: str
    configuration: str
    level_rms: float
    band_hz: tuple[float, float]
    provenance: dict
    freq_hz: np.ndarray
    mean: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    phase_deg: np.ndarray | None

    @property
    def label(self) -> str:
        what = ("apparent mass" if self.quantity == "apparent_mass"
                else f"seat-to-{self.segment} {self.dof}")
        return f"{what}, {self.direction} at {self.level_rms:g} m/s^2 ({self.configuration})"


def read_reference(path) -> ReferenceDataset:
    """Read and check one reference dataset file (see the module docstring)."""
    import yaml

    from ..params import configuration_names

    path = Path(path)
    where = str(path)

    def fail(field: str, why: str):
        raise ReferenceError(f"{where}: {field}: {why}")

    if not path.is_file():
        raise ReferenceError(f"{where}: reference file not found")
    try:
        text = path.read_text()
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError, UnicodeDecodeError) as e:
        raise ReferenceError(f"{where}: not valid {'JSON' if path.suffix == '.json' else 'YAML'}"
                             f": {' '.join(str(e).split())}") from None
    if not isinstance(data, dict):
        fail("(top level)", "expected a mapping of fields")
    known = {"quantity", "direction", "segment", "dof", "configuration", "level_rms",
             "band_hz", "provenance", "data"}
    unknown = sorted(set(data) - known)
    if unknown:
        fail(unknown[0], f"unknown field (known: {', '.join(sorted(known))})")

    def need(key):
        if key not in data or data[key] is None:
            fail(key, "missing")
        return data[key]

    quantity = need("quantity")
    if quantity not in QUANTITIES:
        fail("quantity", f"{quantity!r} is not one of {', '.join(QUANTITIES)}")
    direction = need("direction")
    if direction not in ("x", "y", "z"):
        fail("direction", f"{direction!r} is not x, y or z")
    segment, dof = "seat", direction
    if quantity == "transmissibility":
        segment, dof = need("segment"), need("dof")
        if segment not in SEGMENTS:
            fail("segment", f"{segment!r} is not one of {', '.join(SEGMENTS)}")
        if dof not in DOFS:
            fail("dof", f"{dof!r} is not one of {', '.join(DOFS)}")
    elif direction != "z":
        fail("direction", "the apparent mass is compared for vertical excitation (z) only")
    configuration = need("configuration")
    if configuration not in configuration_names():
        fail("configuration", f"{configuration!r} is not one of "
                              f"{', '.join(configuration_names())}")
    level = need("level_rms")
    if isinstance(level, bool) or not isinstance(level, (int, float)) \
            or not math.isfinite(level) or not level > 0:
        fail("level_rms", f"must be a positive number (m/s^2 r.m.s.), got {level!r}")
    if level > 20:
        fail("level_rms", f"{level!r} m/s^2 r.m.s. is beyond whole-body vibration tests "
                          "(give m/s^2, not mm/s^2 or g)")
    band = data.get("band_hz", [0.5, 20.0])
    if not (isinstance(band, (list, tuple)) and len(band) == 2
            and all(isinstance(b, (int, float)) and not isinstance(b, bool) for b in band)
            and 0 < band[0] < band[1] <= 50):
        fail("band_hz", f"expected [low, high] Hz with 0 < low < high <= 50, got {band!r}")
    prov = need("provenance")
    if not isinstance(prov, dict):
        fail("provenance", "expected a mapping")
    for k in PROVENANCE_FIELDS:
        if not isinstance(prov.get(k), str) or not prov[k].strip():
            fail(f"provenance.{k}", "missing (a short text)")
    d = need("data")
    if not isinstance(d, dict):
        fail("data", "expected a mapping of lists")
    arrays = {}
    for k in ("freq_hz", "mean", "lower", "upper", "phase_deg"):
        if k not in d:
            if k == "phase_deg":
                continue
            fail(f"data.{k}", "missing")
        v = d[k]
        if not isinstance(v, list) or not v:
            fail(f"data.{k}", "expected a non-empty list of numbers")
        try:
            a = np.array([float(x) if not isinstance(x, bool) else math.nan for x in v])
        except (TypeError, ValueError):
            fail(f"data.{k}", "expected numbers")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            fail(f"data.{k}[{bad[0]}]", f"not a finite number ({v[bad[0]]!r})")
        arrays[k] = a
    n = len(arrays["freq_hz"])
    for k, a in arrays.items():
        if len(a) != n:
            fail(f"data.{k}", f"has {len(a)} values, freq_hz has {n}")
    f = arrays["freq_hz"]
    if np.any(f <= 0) or np.any(np.diff(f) <= 0):
        fail("data.freq_hz", "must be positive and increasing")
    for k in ("mean", "lower", "upper"):
        if np.any(arrays[k] < 0):
            fail(f"data.{k}", "a modulus is never negative")
    i = np.flatnonzero((arrays["lower"] > arrays["mean"]) | (arrays["mean"] > arrays["upper"]))
    if i.size:
        fail(f"data (at {f[i[0]]:g} Hz)", "lower <= mean <= upper does not hold")
    if not np.any((f >= COMPARE_BAND_HZ[0]) & (f <= COMPARE_BAND_HZ[1])):
        fail("data.freq_hz", f"no frequency within {COMPARE_BAND_HZ[0]:g}-"
                             f"{COMPARE_BAND_HZ[1]:g} Hz, the model's analysis band")
    return ReferenceDataset(path, quantity, direction, segment, dof, configuration,
                            float(level), (float(band[0]), float(band[1])), dict(prov),
                            f, arrays["mean"], arrays["lower"], arrays["upper"],
                            arrays.get("phase_deg"))


def model_curve(ds: ReferenceDataset, measures, frf=None):
    """(frequency, modulus, phase_deg or None) of the model for `ds`, from a
    run's `RunMeasures` (apparent mass) or its `FrfData` `frf`."""
    if ds.quantity == "apparent_mass":
        return measures.freq_hz, measures.apparent_mass, None
    f, gain, phase, _ = frf.get(ds.direction, ds.segment, ds.dof)
    return f, gain, phase


def compare(ds: ReferenceDataset, f_model, modulus, phase=None) -> dict:
    """The comparison's figures (see the module docstring)."""
    from .run import peak_frequency

    sel = (ds.freq_hz >= COMPARE_BAND_HZ[0]) & (ds.freq_hz <= COMPARE_BAND_HZ[1])
    f = ds.freq_hz[sel]
    m = np.interp(f, f_model, modulus)
    inside = (m >= ds.lower[sel]) & (m <= ds.upper[sel])
    band = (max(COMPARE_BAND_HZ[0], f[0]), min(COMPARE_BAND_HZ[1], f[-1]))
    fine = np.linspace(*band, 2000)
    f_peak_data = peak_frequency(fine, np.interp(fine, f, ds.mean[sel]), band)
    f_peak_model = peak_frequency(fine, np.interp(fine, f_model, modulus), band)
    peak_data = float(np.max(ds.mean[sel]))
    peak_model = float(np.max(m))
    out = {"dataset": str(ds.path), "label": ds.label, "provenance": ds.provenance,
           "frequencies_compared": int(sel.sum()),
           "share_inside_range": float(np.mean(inside)),
           "peak_frequency_hz": {"data": f_peak_data, "model": f_peak_model,
                                 "error_hz": f_peak_model - f_peak_data},
           "peak_modulus": {"data": peak_data, "model": peak_model,
                            "relative_error": peak_model / peak_data - 1.0},
           "median_relative_error": float(np.median(np.abs(m / ds.mean[sel] - 1.0)))}
    if ds.phase_deg is not None and phase is not None:
        d = np.angle(np.exp(1j * np.radians(np.interp(f, f_model, phase)
                                            - ds.phase_deg[sel])), deg=True)
        out["phase_rms_difference_deg"] = float(np.sqrt(np.mean(d * d)))
    return out


__all__ = ["COMPARE_BAND_HZ", "PROVENANCE_FIELDS", "ReferenceDataset", "ReferenceError",
           "compare", "model_curve", "read_reference"]
