"""Validation: the model against published facts of seated-human biodynamics
and against measured datasets a lab supplies (`ehm-drake validate`).

* `facts`: the shipped facts (statement, citation and DOI, quantity,
  configuration, level, expected range and why) and the runs they need;
* `run`: the model run in a fact's configuration (nonlinear time domain,
  with its equivalent-linear prediction beside it);
* `reference`: the documented format of a lab's dataset and the frequency
  by frequency comparison;
* `report`: ``validation.json``, ``validation.md`` and the figures.
"""

from .facts import FACTS, RUNS, Fact, Run, Source
from .reference import ReferenceDataset, ReferenceError, compare, read_reference
from .report import validate

__all__ = ["FACTS", "RUNS", "Fact", "ReferenceDataset", "ReferenceError", "Run", "Source",
           "compare", "read_reference", "validate"]
