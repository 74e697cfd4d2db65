"""Measured-data file formats: ``frf.csv`` and ``timeseries.csv``.

Two plain-text formats carry measured (or simulated) seated whole-body-vibration data.
Several tools read them, so they are kept exactly as specified here.

``frf.csv`` -- transmissibilities, one row per frequency bin::

    direction,segment,dof,freq_hz,gain,phase_deg,coherence[,level_rms]

* ``direction`` -- seat excitation axis, one of ``x``, ``y``, ``z``;
* ``segment`` -- one of ``pelvis``, ``trunk``, ``head``, ``knee_l``, ``knee_r``;
* ``dof`` -- one of ``x``, ``y``, ``z``, ``roll``, ``pitch``, ``yaw``;
* ``freq_hz`` -- frequency (Hz, > 0);
* ``gain`` -- |T|, per metre of seat displacement: m/m for translational dofs,
  deg/m for rotational dofs (>= 0);
* ``phase_deg`` -- phase of T (deg);
* ``coherence`` -- ordinary (or multiple) coherence, in [0, 1];
* ``level_rms`` -- optional: seat acceleration RMS of the test (m/s^2, > 0). An empty cell
  means "not given" and is read as NaN.
* ``n_averages`` -- optional: number of (Welch) averages of the estimate (>= 1); with the
  coherence it gives the estimate's random error.  An empty cell means "not given" (NaN).

``timeseries.csv`` -- time histories on seat-aligned axes::

    t,seat_ax,seat_ay,seat_az,<segment>_<dof>,...

* ``t`` -- time (s), uniformly sampled and increasing;
* ``seat_ax``, ``seat_ay``, ``seat_az`` -- seat acceleration (m/s^2), all three required;
* ``<segment>_<dof>`` -- absolute motion from the settled pose: displacement in m for
  translational dofs, rotation in deg for rotational dofs, e.g. ``head_pitch``, ``knee_l_z``.

Optional metadata ``level_rms`` (m/s^2) and ``direction`` (excited axis or axes, e.g. ``"z"`` or
``"xz"``) come either from a one-line JSON comment as the first line of the file
(``# {"level_rms": 0.3, "direction": "z"}``) or from a sidecar ``meta.json`` in the same folder.
When both exist they are merged; a key given in both with different values is an error.

All readers validate their input and raise :class:`DataFormatError` (a ``ValueError``) whose
message names the file, the line and the column at fault.  Python warnings are never emitted;
:func:`check_units` returns plausibility warnings as strings instead.

Modules: :mod:`.common` (:class:`DataFormatError`, the label vocabulary, channel names and
units, the CSV parsing shared by the readers), :mod:`.frf` (``frf.csv``, :func:`check_units`),
:mod:`.timeseries` (``timeseries.csv`` and its comment-line metadata), :mod:`.metadata`
(``meta.json``, the test list ``tests.json`` and the metadata checks) and :mod:`.folder`
(:func:`read_data_dir`).  The public names are re-exported here.

Motion-capture sessions in C3D files (markers and analog channels, https://www.c3d.org) are
read and written by :mod:`.c3d` (not re-exported: it imports ezc3d) and reduced to
``timeseries.csv`` records by :mod:`ehm_drake.analysis.mocap` with a lab's marker map
(:mod:`ehm_drake.analysis.marker_map`).
"""

from .common import (
    DIRECTIONS,
    DOFS,
    ROTATIONAL_DOFS,
    SEGMENTS,
    TRANSLATIONAL_DOFS,
    DataFormatError,
    channel_unit,
    parse_channel_name,
)
from .folder import read_data_dir
from .frf import FRF_COLUMNS, FrfData, check_units, read_frf
from .metadata import TESTS_FILENAME, find_test_timeseries, write_test_list
from .timeseries import (
    MIN_DURATION_S,
    MIN_SAMPLES,
    SAMPLING_RTOL,
    SEAT_COLUMNS,
    TimeSeriesData,
    read_timeseries,
)

__all__ = [
    "DIRECTIONS",
    "SEGMENTS",
    "DOFS",
    "TRANSLATIONAL_DOFS",
    "ROTATIONAL_DOFS",
    "FRF_COLUMNS",
    "SEAT_COLUMNS",
    "MIN_DURATION_S",
    "MIN_SAMPLES",
    "SAMPLING_RTOL",
    "DataFormatError",
    "FrfData",
    "TimeSeriesData",
    "parse_channel_name",
    "channel_unit",
    "read_frf",
    "read_timeseries",
    "read_data_dir",
    "check_units",
    "TESTS_FILENAME",
    "find_test_timeseries",
    "write_test_list",
]
