"""The published facts the model is checked against, and the simulations
(configuration, excitation, level) that check them.

Each fact is a statement of a published study, paraphrased, with its
citation and DOI, the quantity the model must reproduce, the range that
counts as reproducing it, and how that range was set.  Only facts that
could be read here (abstracts, open articles, a handbook's summary) are
shipped; where a study's conditions could not be read, the assumption made
is stated with the fact.  Which facts set the model's parameters (and so
are not independent checks) is said in `Fact.calibration`.

What remains unknown without measured curves: the whole frequency response
(gain and phase per channel), the peak moduli, the spread between people;
`ehm-drake validate --reference FILE` compares a measured dataset bin by bin
(`ehm_drake.validation.reference`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Source:
    key: str
    citation: str
    doi: str
    #: What was read (the abstract, the open text, a handbook's summary).
    read: str


@dataclass(frozen=True)
class Run:
    """One simulation: a configuration (`ehm_drake/data/configurations`), a
    seat excitation (random in a band, or a sinusoid) in `direction` at
    `level_rms` (m/s^2 r.m.s. per axis)."""

    key: str
    configuration: str
    direction: str
    level_rms: float
    kind: str = "random"  # "random" or "sine"
    band_hz: tuple[float, float] = (0.5, 20.0)
    frequency_hz: float = 0.0  # sine only

    def describe(self) -> str:
        what = (f"random {self.band_hz[0]:g}-{self.band_hz[1]:g} Hz" if self.kind == "random"
                else f"sine {self.frequency_hz:g} Hz")
        return f"{self.configuration}, {self.direction} {what}, {self.level_rms:g} m/s^2 r.m.s."


@dataclass(frozen=True)
class Fact:
    id: str
    source: Source
    #: The published statement, paraphrased.
    statement: str
    #: What the model's value is (with its unit).
    quantity: str
    unit: str
    #: The configuration and excitation, in words (with assumptions).
    configuration: str
    level_rms: tuple[float, ...]
    #: The range that counts as reproducing the fact: [low, high] (None:
    #: unbounded), and why.
    expected: tuple[float | None, float | None]
    expected_reason: str
    runs: tuple[str, ...]
    #: The model's value from the runs' measures ({run key: RunMeasures}).
    evaluate: Callable[[dict], float] = field(repr=False, compare=False)
    #: Non-empty when the fact set a model parameter (not an independent check).
    calibration: str = ""

    def passed(self, value: float) -> bool:
        lo, hi = self.expected
        return bool(np.isfinite(value) and (lo is None or value >= lo)
                    and (hi is None or value <= hi))

    def expected_text(self) -> str:
        lo, hi = self.expected
        if lo is not None and hi is not None:
            return f"{lo:g} to {hi:g} {self.unit}".rstrip()
        if lo is not None:
            return f">= {lo:g} {self.unit}".rstrip()
        return f"<= {hi:g} {self.unit}".rstrip()


# ---------------------------------------------------------------------------
# Sources
# ---------------------------------------------------------------------------

FAIRLEY_GRIFFIN_1989 = Source(
    "fairley_griffin_1989",
    "Fairley TE, Griffin MJ. The apparent mass of the seated human body: vertical vibration. "
    "J Biomech 22(2):81-94, 1989 (60 subjects)",
    "10.1016/0021-9290(89)90031-6",
    "the abstract's summary as given in this project's issue and a handbook's summary "
    "(Biomedical Engineering and Design Handbook, vol. 1, ch. 11): resonance about 6 Hz at "
    "0.25 and about 4 Hz at 2.0 m/s^2 r.m.s.; higher with a backrest; legs moving with the "
    "seat")
MANSFIELD_MAEDA_2005 = Source(
    "mansfield_maeda_2005",
    "Mansfield NJ, Maeda S. Effect of backrest and torso twist on the apparent mass of the "
    "seated body exposed to vertical vibration. Ind Health 43(3):413-420, 2005 (12 men)",
    "10.2486/indhealth.43.413",
    "the abstract (J-STAGE): vertical random vibration 0.4 m/s^2 r.m.s.; apparent-mass peak "
    "near 6 Hz back on, back off and twisted")
MATSUMOTO_GRIFFIN_2002 = Source(
    "matsumoto_griffin_2002",
    "Matsumoto Y, Griffin MJ. Effect of muscle tension on non-linearities in the apparent "
    "masses of seated subjects exposed to vertical whole-body vibration. J Sound Vib "
    "253(1):77-92, 2002 (8 men)",
    "10.1006/jsvi.2001.4250",
    "the abstract: random 2-20 Hz, 60 s, 0.35 to 1.4 m/s^2 r.m.s.; resonance 5.25 -> 4.25 Hz "
    "with normal muscle tension")
GOGGINS_2022 = Source(
    "goggins_2022",
    "Goggins KA, Kelly EA, Thompson TJ, Eger TR. Examining the impact of rotated neck and "
    "trunk postures on vertical seat-to-head vibration transmissibility and self-reported "
    "discomfort. Vibration 5(2):306-325, 2022 (11 participants)",
    "10.3390/vibration5020018",
    "the abstract (open access): vertical sinusoid 3 Hz, 0.7 m/s^2; seat-to-head "
    "transmissibility above 1 in every condition")

SOURCES = (FAIRLEY_GRIFFIN_1989, MANSFIELD_MAEDA_2005, MATSUMOTO_GRIFFIN_2002, GOGGINS_2022)

# ---------------------------------------------------------------------------
# Runs
# ---------------------------------------------------------------------------

#: F&G's and M&M's excitation bands could not be read here: the random
#: 0.5-20 Hz of Huang & Griffin 2006 (J Sound Vib 298:824-840), who repeated
#: the 0.25 and 2.0 m/s^2 of Fairley & Griffin, is assumed for both.
LAB_BAND = (0.5, 20.0)
RUNS: dict[str, Run] = {r.key: r for r in (
    Run("rigid_0.25", "rigid_seat", "z", 0.25, band_hz=LAB_BAND),
    Run("rigid_2.0", "rigid_seat", "z", 2.0, band_hz=LAB_BAND),
    Run("rigid_back_0.25", "rigid_seat_backrest", "z", 0.25, band_hz=LAB_BAND),
    Run("rigid_back_2.0", "rigid_seat_backrest", "z", 2.0, band_hz=LAB_BAND),
    Run("rigid_0.4", "rigid_seat", "z", 0.4, band_hz=LAB_BAND),
    Run("rigid_back_0.4", "rigid_seat_backrest", "z", 0.4, band_hz=LAB_BAND),
    Run("rigid_0.35_2-20", "rigid_seat", "z", 0.35, band_hz=(2.0, 20.0)),
    Run("rigid_1.4_2-20", "rigid_seat", "z", 1.4, band_hz=(2.0, 20.0)),
    Run("car_sine_3hz_0.7", "car_seat", "z", 0.7, kind="sine", frequency_hz=3.0),
)}


# ---------------------------------------------------------------------------
# Facts
# ---------------------------------------------------------------------------


def _resonance(run: str):
    return lambda m: m[run].resonance_hz


def _backrest_difference(m) -> float:
    """The smaller of the backrest's shifts at 0.25 and 2.0 m/s^2 (Hz)."""
    return min(m["rigid_back_0.25"].resonance_hz - m["rigid_0.25"].resonance_hz,
               m["rigid_back_2.0"].resonance_hz - m["rigid_2.0"].resonance_hz)


FACTS: tuple[Fact, ...] = (
    Fact("fg1989_resonance_0.25", FAIRLEY_GRIFFIN_1989,
         "On a rigid seat without backrest the vertical apparent mass resonates at about 6 Hz "
         "at 0.25 m/s^2 r.m.s.",
         "frequency of the peak of the normalized vertical apparent mass", "Hz",
         "rigid flat seat, no backrest, upright; feet moving with the seat; hands on the "
         "thighs (assumed); random 0.5-20 Hz (assumed)", (0.25,),
         (5.0, 7.0), "about 6 Hz; 5-7 Hz covers the spread of the mean between studies",
         ("rigid_0.25",), _resonance("rigid_0.25"),
         calibration="the tissue's stiffness at rest was set to give about 6 Hz here"),
    Fact("fg1989_resonance_2.0", FAIRLEY_GRIFFIN_1989,
         "The resonance falls to about 4 Hz at 2.0 m/s^2 r.m.s.: the body softens as the "
         "vibration grows.",
         "frequency of the peak of the normalized vertical apparent mass", "Hz",
         "as fg1989_resonance_0.25, at 2.0 m/s^2", (2.0,),
         (3.3, 5.0), "about 4 Hz", ("rigid_2.0",), _resonance("rigid_2.0"),
         calibration="the softening's critical amplitude and maximum loss were set with it"),
    Fact("fg1989_backrest", FAIRLEY_GRIFFIN_1989,
         "Leaning against a rigid backrest raises the resonance (Fairley & Griffin); at "
         "0.4 m/s^2 Mansfield & Maeda found it about the same with and without.",
         "resonance with the rigid backrest minus without, the smaller at 0.25 and 2.0 m/s^2",
         "Hz", "rigid seat with and without a rigid vertical backrest; as above", (0.25, 2.0),
         (-0.1, None), "not lower with the backrest, within one frequency bin (0.1 Hz)",
         ("rigid_0.25", "rigid_2.0", "rigid_back_0.25", "rigid_back_2.0"),
         _backrest_difference),
    Fact("mm2005_back_on", MANSFIELD_MAEDA_2005,
         "With the back against the backrest the vertical apparent mass peaks near 6 Hz at "
         "0.4 m/s^2 r.m.s.",
         "frequency of the peak of the normalized vertical apparent mass", "Hz",
         "rigid seat, rigid vertical backrest, back on; random 0.5-20 Hz (assumed)", (0.4,),
         (5.0, 7.0), "near 6 Hz", ("rigid_back_0.4",), _resonance("rigid_back_0.4")),
    Fact("mm2005_back_off", MANSFIELD_MAEDA_2005,
         "With the back off the backrest the peak is also near 6 Hz at 0.4 m/s^2 r.m.s.",
         "frequency of the peak of the normalized vertical apparent mass", "Hz",
         "rigid seat, back off (no backrest); random 0.5-20 Hz (assumed)", (0.4,),
         (5.0, 7.0), "near 6 Hz", ("rigid_0.4",), _resonance("rigid_0.4")),
    Fact("mg2002_softening_ratio", MATSUMOTO_GRIFFIN_2002,
         "The apparent-mass resonance fell from 5.25 to 4.25 Hz as random vertical vibration "
         "rose from 0.35 to 1.4 m/s^2 r.m.s. (normal muscle tension).",
         "resonance at 1.4 m/s^2 over resonance at 0.35 m/s^2", "",
         "rigid seat without backrest (seat and backrest not stated in the abstract: "
         "assumed); random 2-20 Hz as in the study", (0.35, 1.4),
         (0.70, 0.92), "0.81 measured (8 men); +-0.11 for the subjects' spread, not given in "
         "the abstract", ("rigid_0.35_2-20", "rigid_1.4_2-20"),
         lambda m: m["rigid_1.4_2-20"].resonance_hz / m["rigid_0.35_2-20"].resonance_hz),
    Fact("goggins2022_head_3hz", GOGGINS_2022,
         "At 3 Hz, 0.7 m/s^2 vertical, the head moved more than the seat in every posture "
         "(seat-to-head vertical transmissibility above 1).",
         "seat-to-head vertical transmissibility at 3 Hz", "m/m",
         "the car seat (the study's seat, an industrial one, could not be read: assumed); "
         "erect posture", (0.7,),
         (1.0, None), "above 1", ("car_sine_3hz_0.7",),
         lambda m: m["car_sine_3hz_0.7"].head_z_at(3.0)),
)


def fact_by_id(fact_id: str) -> Fact:
    for f in FACTS:
        if f.id == fact_id:
            return f
    raise KeyError(fact_id)


def runs_for(facts) -> list[Run]:
    """The runs the facts need, each once, in `RUNS` order."""
    keys = {k for f in facts for k in f.runs}
    return [r for k, r in RUNS.items() if k in keys]


__all__ = ["FACTS", "Fact", "LAB_BAND", "RUNS", "Run", "SOURCES", "Source", "fact_by_id",
           "runs_for"]
