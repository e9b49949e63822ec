"""The job layer: one input from its settings to its written files, the same for every front end
(``nurbs-fit``, the batch runner and its Dask workers; the Python API through :class:`FitJob`).

* :mod:`.settings`: :class:`FitJob` (plain, picklable settings with the command line's defaults)
  and the engine configurations it gives (FitConfig, PatchOptions);
* :mod:`.checks`: outputs and options checked before any work;
* :mod:`.one_input`: :func:`fit_one`, the route of one input (the automatic one decided by
  :mod:`nurbs_core.route`) with its fallbacks;
* :mod:`.single`: one patch or curve in three steps (:func:`prepare_fit`, :func:`run_fit`,
  :func:`finish_fit`) that a batch runs apart around one ``fit_batch``;
* :mod:`.network`, :mod:`.part`: a patch network, a machined part's solid;
* :mod:`.report`: progress lines, the report, the error line, exit statuses.

Front ends import from here; nothing here imports a front end. Nothing heavy at import: numpy,
the engine and torch load where a step needs them.
"""

from __future__ import annotations

from nurbs_core.jobs.one_input import fit_one
from nurbs_core.jobs.report import INTERRUPTED_STATUS, SOME_FAILED_STATUS, FitFailed, error_line
from nurbs_core.jobs.settings import FitJob, fit_config, patch_options
from nurbs_core.jobs.single import PreparedFit, finish_fit, prepare_fit, run_fit

__all__ = ["INTERRUPTED_STATUS", "SOME_FAILED_STATUS", "FitFailed", "FitJob", "PreparedFit",
           "error_line", "finish_fit", "fit_config", "fit_one", "patch_options", "prepare_fit",
           "run_fit"]
