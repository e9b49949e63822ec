"""What a batch is: :class:`BatchSettings`, its inputs, where the results go, how they are run,
and the :class:`nurbs_core.jobs.FitJob` every input is fitted with."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from nurbs_core.jobs.settings import FitJob

#: Default of ``--batch-fits``: how many ``--grid`` inputs of a batch are fitted together.
DEFAULT_BATCH_FITS = 32


@dataclass
class BatchSettings:
    """``nurbs-fit IN... --output-dir DIR``'s settings: ``inputs`` (files, folders, globs, HDF5
    files), the results' folder and suffix (``format``), the ``summary`` table (default
    DIR/summary.jsonl), ``skip_existing`` inputs whose result exists, ``jobs`` local Dask workers
    or an existing cluster's ``scheduler``, ``batch_fits`` ``--grid`` inputs fitted together, and
    ``job``: the settings of every input (its ``input`` and ``output`` are each item's)."""

    inputs: list[str]
    output_dir: str
    job: FitJob = field(default_factory=lambda: FitJob(input=""))
    format: str = ".json"
    summary: str | None = None
    skip_existing: bool = False
    jobs: int = 1
    scheduler: str | None = None
    batch_fits: int = DEFAULT_BATCH_FITS

    @classmethod
    def of(cls, values: Any) -> BatchSettings:
        """The batch of an object with these fields as attributes (an argparse Namespace whose
        ``input`` lists the inputs; the rest are the FitJob's)."""
        return cls(inputs=list(values.input), output_dir=values.output_dir,
                   job=FitJob.of(values, input="", output=[]), format=values.format,
                   summary=values.summary, skip_existing=values.skip_existing, jobs=values.jobs,
                   scheduler=values.scheduler, batch_fits=values.batch_fits)
