"""ehm_drake: an efficient seated human body model on Drake (see README.md)."""

# The gap diagnosis' candidate effects register as model extensions (see
# ehm_drake.model.extensions), so an `effects` mapping resolves wherever the
# model is built; the module is light (no Drake at import).
from .gap.library import effects as _effects  # noqa: F401
from .parallel import pin_blas_threads as _pin_blas_threads

# One BLAS thread per process unless $EHM_DRAKE_BLAS_THREADS says otherwise:
# results do not depend on the machine's thread count (see ehm_drake.parallel).
_pin_blas_threads()
