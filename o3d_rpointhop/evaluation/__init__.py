"""Benchmarks: one module per dataset (:mod:`.modelnet40`, :mod:`.bunny`,
:mod:`.threedmatch`, :mod:`.multiway`), the methods compared (:mod:`.methods`), the
pair protocols (:mod:`.protocols`), the metrics (:mod:`.metrics`) and the reports, with
timings kept apart from the deterministic results (:mod:`.report`). The command line
runs them: ``o3d-rpointhop benchmark DATASET``."""
