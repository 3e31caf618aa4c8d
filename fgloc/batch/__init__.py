"""``fgloc batch``: many logs (or benchmark seeds) with the single-log code, on one machine or a Ray cluster.

::

    fgloc batch run runs/ 'fleet/**/*.mcap' --map hall.yaml -o out/        # local pool, all cores
    fgloc batch run --manifest fleet.csv -o out/ --engine ray -j 8          # private local Ray instance
    fgloc batch run --manifest fleet.csv -o out/ --engine ray --address head:6379 --ship-inputs
    fgloc batch map logs/*.clf.bz2 -o maps/
    fgloc batch bench paper --seeds 100 --engine ray -o bench/

Every job calls the same library function as the single-log command (through
:mod:`fgloc.batch.adapter`) and writes the same files into ``OUTDIR/<log-name>/``, so a
batch result is byte-identical to ``fgloc run LOG ... -o OUTDIR/<log-name>`` with the same
(absolute) paths; ``OUTDIR/summary.csv`` has one row per log.

Engines (:mod:`fgloc.batch.engines`): ``local`` (a process pool, ``-j N``) and ``ray``
(without ``--address``/``RAY_ADDRESS``: a private local instance with ``-j`` or all CPUs; with
it: that cluster).  Ray is optional (``pip install "fgloc[cluster]"``).

Inputs reach the workers (:mod:`fgloc.batch.jobs`):

* **by path** (default): workers open the logs, maps and config by absolute path and write
  their outputs straight into ``OUTDIR``; on a cluster every node must see the same paths
  (shared storage);
* **as data** (``--ship-inputs``): the driver reads every input (a map YAML with its image) and
  puts the bytes in Ray's object store (once per distinct file), the worker materializes them
  in a temporary folder under their original names, runs there and sends its output files
  back; the driver writes them into ``OUTDIR``.  No shared storage needed; outputs and error
  messages name the original paths.

Resumption and failures (:mod:`fgloc.batch.runner`): a finished job has a completion
marker (``batch-done.json``, written last); running again skips it unless ``--force`` (or its
options or inputs changed); a failing log gets its one-line error in the summary and the
others go on; Ctrl-C keeps every finished log.
"""

from fgloc.batch.api import BenchReport, EngineOptions, batch_bench_paper, batch_map, batch_run
from fgloc.batch.engines import InlineEngine, LocalEngine, RayEngine, make_engine
from fgloc.batch.jobs import Job, JobResult, execute
from fgloc.batch.runner import MARKER, BatchReport, run_batch
from fgloc.batch.summary import COLUMNS, SummaryRow, read_summary_csv, summary_table

__all__ = [
    "COLUMNS", "MARKER", "BatchReport", "BenchReport", "EngineOptions", "InlineEngine", "Job", "JobResult",
    "LocalEngine", "RayEngine", "SummaryRow", "batch_bench_paper", "batch_map", "batch_run", "execute",
    "make_engine", "read_summary_csv", "run_batch", "summary_table",
]
