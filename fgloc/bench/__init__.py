"""Benchmarks behind ``fgloc bench`` and ``fgloc demo``: library functions that return numbers.

* :func:`localize_sim` - one back-end/front-end over a simulated run; :func:`localize_variants`
  - several (the paper's variants) over one run;
* :mod:`fgloc.bench.paper` - the paper replica over seeds (:func:`bench_paper`);
* :mod:`fgloc.bench.faults` - fault scenarios, kidnap recovery (:func:`bench_faults`,
  :func:`kidnap_recovery`).
"""

from fgloc.bench.common import frontend_available, localize_sim, localize_variants
from fgloc.bench.faults import FAULTS, bench_faults, kidnap_recovery
from fgloc.bench.paper import PAPER_VARIANTS, bench_paper, claims, paper_variants

__all__ = ["FAULTS", "PAPER_VARIANTS", "bench_faults", "bench_paper", "claims", "frontend_available",
           "kidnap_recovery", "localize_sim", "localize_variants", "paper_variants"]
