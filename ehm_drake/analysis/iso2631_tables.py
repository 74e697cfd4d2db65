"""Reference data: ISO 2631-1:1997 weighting parameters and tabulated weighting factors.

Contents
--------
``WEIGHTING_PARAMETERS``
    Parameters of the analog weighting filters (ISO 2631-1:1997 Annex A, Table A.1;
    identical in ISO 8041:2005 Table 3): band-limiting high-pass ``f1`` and low-pass ``f2``
    (2nd-order Butterworth, ``Q1 = Q2 = 1/sqrt(2)``), acceleration-velocity transition
    ``f3, f4, Q4`` and upward step ``f5, Q5, f6, Q6``; ``inf`` marks an absent term.
``WEIGHTING_FACTORS_X1000``
    The standard's tabulated weighting factors x 1000 at the nominal one-third-octave band
    centre frequencies (ISO 2631-1:1997 Table 3 -- principal weightings Wk, Wd, Wf -- and
    Table 4 -- additional weightings Wc, We, Wj).  Values are kept as the printed strings
    so that their rounding (number of digits) is known.

Sources
-------
The standard itself is not freely available; the values were taken from public
transcriptions found with a code-search index (stored copies of public GitHub files) and
cross-checked against each other and against the exact Annex A formula:

* parameters: Larson Davis *HVM200 Reference Manual*, Table 3.1 "Parameters and transfer
  functions of the frequency weightings (source: ISO 8041)"
  (https://www.easymanua.ls/larson-davis/hvm200/manual/686640?p=30 and
  https://manualshive.com/en/manual/larson-davis/hvm200/3698114?page=33); the same values
  appear in E. L. Zechmann's MATLAB ``whole_body_filter.m`` (ISO 2631-1:1997 constants);
* Wk, Wd, Wf, Wc, We, Wj at 0.1-80 Hz (Wf 0.02-4 Hz): a public Python script, class
  ``ISO2631Analyzer``, dict ``frequency_weightings`` commented "Exact frequency weightings
  from ISO 2631-1 Tables 3 and 4" (index file id 25104960787; its repository name is not
  exposed by the index);
* Wk and Wd at 0.1-400 Hz: a public Python function ``overall_aw_value`` (index file id
  18026302511), agreeing with the above at 0.1-80 Hz;
* Wk, Wd, Wc at 0.5-80 Hz: a public C# class ``RideComfortUC.Models.TimeHisResult``
  (index file id 42047033972), agreeing with the above;
* Wf at 0.02-4 Hz: a public MATLAB script comparing Wf approximations ("ISO 2631-1 Wf
  (Motion Sickness) szuro kozeliteseinek osszehasonlitasa", index file id 62505681546),
  agreeing with the above.

Known discrepancies (see ``KNOWN_DISCREPANCIES``): the entries are kept as found, and the
tests check that they are the *only* entries that disagree with the Annex A formula.

* Wd at 10 Hz reads 212 in all three independent transcriptions (so very probably in the
  printed standard); the formula gives 201.7, and the neighbours (253 at 8 Hz, 161 at
  12.5 Hz) follow the formula's slope, which points to a misprint of 202.
* Wj at 4 Hz reads 528 in the only transcription found; the formula gives 628.1 and the
  neighbours (524 at 3.15 Hz, 793 at 5 Hz) point to a typo for 628.

The tabulated values reproduce the formula evaluated at the *nominal* band frequencies
(0.315, 0.63, 1.25 Hz, ...), not at the exact ``10^(n/10)`` centre frequencies.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "WEIGHTING_PARAMETERS",
    "NOMINAL_FREQUENCIES_HZ",
    "WF_NOMINAL_FREQUENCIES_HZ",
    "WEIGHTING_FACTORS_X1000",
    "KNOWN_DISCREPANCIES",
    "tabulated_weighting",
    "tabulated_rounding",
]

_INF = math.inf
_Q_BW = 1.0 / math.sqrt(2.0)

#: name -> (f1, Q1, f2, Q2, f3, f4, Q4, f5, Q5, f6, Q6) in Hz / dimensionless.
WEIGHTING_PARAMETERS: dict[str, tuple[float, ...]] = {
    "Wk": (0.4, _Q_BW, 100.0, _Q_BW, 12.5, 12.5, 0.63, 2.37, 0.91, 3.35, 0.91),
    "Wd": (0.4, _Q_BW, 100.0, _Q_BW, 2.0, 2.0, 0.63, _INF, 1.0, _INF, 1.0),
    "Wf": (0.08, _Q_BW, 0.63, _Q_BW, _INF, 0.25, 0.86, 0.0625, 0.80, 0.10, 0.80),
    "Wc": (0.4, _Q_BW, 100.0, _Q_BW, 8.0, 8.0, 0.63, _INF, 1.0, _INF, 1.0),
    "We": (0.4, _Q_BW, 100.0, _Q_BW, 1.0, 1.0, 0.63, _INF, 1.0, _INF, 1.0),
    "Wj": (0.4, _Q_BW, 100.0, _Q_BW, _INF, _INF, 1.0, 3.75, 0.91, 5.32, 0.91),
}

#: Nominal one-third-octave centre frequencies 0.1-400 Hz (Hz).
NOMINAL_FREQUENCIES_HZ: tuple[float, ...] = (
    0.1, 0.125, 0.16, 0.2, 0.25, 0.315, 0.4, 0.5, 0.63, 0.8,
    1.0, 1.25, 1.6, 2.0, 2.5, 3.15, 4.0, 5.0, 6.3, 8.0,
    10.0, 12.5, 16.0, 20.0, 25.0, 31.5, 40.0, 50.0, 63.0, 80.0,
    100.0, 125.0, 160.0, 200.0, 250.0, 315.0, 400.0,
)  # fmt: skip

#: Nominal frequencies of the Wf column (0.02-4 Hz).
WF_NOMINAL_FREQUENCIES_HZ: tuple[float, ...] = (
    0.02, 0.025, 0.0315, 0.04, 0.05, 0.063, 0.08, 0.1, 0.125, 0.16,
    0.2, 0.25, 0.315, 0.4, 0.5, 0.63, 0.8, 1.0, 1.25, 1.6,
    2.0, 2.5, 3.15, 4.0,
)  # fmt: skip

#: name -> weighting factors x 1000 as printed, aligned with the name's frequency list
#: (``WF_NOMINAL_FREQUENCIES_HZ`` for Wf; ``NOMINAL_FREQUENCIES_HZ`` otherwise, truncated to
#: the entries available: 0.1-400 Hz for Wk, Wd; 0.1-80 Hz for Wc, We, Wj).
WEIGHTING_FACTORS_X1000: dict[str, tuple[str, ...]] = {
    "Wk": (
        "31.2", "48.6", "79.0", "121", "182", "263", "352", "418", "459", "477",
        "482", "484", "494", "531", "631", "804", "967", "1039", "1054", "1036",
        "988", "902", "768", "636", "513", "405", "314", "246", "186", "132",
        "88.7", "54.0", "28.5", "15.2", "7.90", "3.98", "1.95",
    ),
    "Wd": (
        "62.4", "97.3", "158", "243", "365", "530", "713", "853", "944", "992",
        "1011", "1008", "968", "890", "776", "642", "512", "409", "323", "253",
        "212", "161", "125", "100", "80.0", "63.2", "49.4", "38.8", "29.5", "21.1",
        "14.1", "8.63", "4.55", "2.43", "1.26", "0.64", "0.31",
    ),
    "Wf": (
        "24.2", "37.7", "59.7", "97.1", "157", "267", "461", "695", "895", "1006",
        "992", "854", "619", "384", "224", "116", "53.0", "23.5", "9.98", "3.77",
        "1.55", "0.64", "0.25", "0.097",
    ),
    "Wc": (
        "62.4", "97.2", "158", "243", "364", "527", "708", "843", "929", "972",
        "991", "1000", "1007", "1012", "1017", "1022", "1024", "1013", "974", "891",
        "776", "647", "512", "409", "325", "256", "199", "156", "118", "84.4",
    ),
    "We": (
        "62.5", "97.5", "159", "245", "368", "536", "723", "862", "939", "941",
        "880", "772", "632", "512", "409", "323", "253", "202", "160", "125",
        "100", "80.1", "62.5", "50.0", "39.9", "31.6", "24.7", "19.4", "14.8", "10.5",
    ),
    "Wj": (
        "31.0", "48.3", "78.5", "120", "181", "262", "351", "417", "458", "478",
        "484", "485", "483", "482", "489", "524", "528", "793", "946", "1017",
        "1030", "1026", "1018", "1012", "1007", "1001", "991", "972", "931", "843",
    ),
}  # fmt: skip

#: (name, nominal frequency) -> explanation, for entries inconsistent with the formula.
KNOWN_DISCREPANCIES: dict[tuple[str, float], str] = {
    ("Wd", 10.0): "printed 212 (three transcriptions agree); formula 201.7, probably 202",
    ("Wj", 4.0): "transcribed 528; formula 628.1, neighbours point to a typo for 628",
}


def _frequencies(name: str) -> tuple[float, ...]:
    if name not in WEIGHTING_FACTORS_X1000:
        raise ValueError(
            f"no tabulated factors for weighting '{name}'; available: "
            f"{sorted(WEIGHTING_FACTORS_X1000)}"
        )
    freqs = WF_NOMINAL_FREQUENCIES_HZ if name == "Wf" else NOMINAL_FREQUENCIES_HZ
    return freqs[: len(WEIGHTING_FACTORS_X1000[name])]


def tabulated_weighting(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Tabulated weighting of ``name`` as ``(nominal frequency in Hz, factor)``.

    The factor is the printed value / 1000 (dimensionless gain).
    """
    freqs = _frequencies(name)
    vals = np.array([float(v) for v in WEIGHTING_FACTORS_X1000[name]]) / 1000.0
    return np.asarray(freqs, dtype=float), vals


def tabulated_rounding(name: str) -> np.ndarray:
    """Relative half-unit of the last printed digit of each tabulated factor.

    E.g. "0.64" -> 0.005 / 0.64 = 0.78 %, "1054" -> 0.5 / 1054 = 0.05 %.  This is the
    relative error the rounding of the table alone can explain.
    """
    _frequencies(name)
    out = []
    for s in WEIGHTING_FACTORS_X1000[name]:
        decimals = len(s.split(".")[1]) if "." in s else 0
        out.append(0.5 * 10.0 ** (-decimals) / float(s))
    return np.asarray(out)
