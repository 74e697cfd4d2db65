"""Reality `spine5`: a seated human with a five-body spine, written
independently of the EHM model (see `reality.Spine5Reality`, the parameter
table in `params`, the effects in `effects`)."""

from __future__ import annotations

from .. import register_reality
from .reality import Spine5Prepared, Spine5Reality, Spine5Run

register_reality(Spine5Reality)

__all__ = ["Spine5Prepared", "Spine5Reality", "Spine5Run"]
