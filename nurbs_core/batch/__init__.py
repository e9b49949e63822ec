"""Batch fitting for ``nurbs-fit``: many inputs, one result each, a summary table.

``nurbs-fit IN... --output-dir DIR`` expands the inputs (:mod:`.inputs`: files, folders, globs,
HDF5 datasets of clouds), fits each through :func:`nurbs_core.jobs.fit_one` (the single-file code
path, so every result equals a one-file run with the same options), or, for clouds with the known
parameters of ``--grid``, chunks of ``--batch-fits`` inputs through ``prepare_fit``, one
:func:`nurbs_core.fitting.fit_batch` and ``finish_fit`` (the engine's batch dimension; each result
equals the single run's to 1e-9), in this process or on Dask workers (:mod:`.executors`),
shows a progress line and writes the summary (:mod:`.runner`); :class:`BatchSettings` holds
what the run is (:mod:`.settings`).
Workers receive file paths and one :class:`nurbs_core.jobs.FitJob` and return plain dicts (:mod:`.worker`): no
tensor crosses a process. Nothing here imports torch or Dask at module level.
"""

from __future__ import annotations

from nurbs_core.batch.runner import run_batch
from nurbs_core.batch.settings import DEFAULT_BATCH_FITS, BatchSettings

__all__ = ["DEFAULT_BATCH_FITS", "BatchSettings", "run_batch"]
