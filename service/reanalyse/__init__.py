"""Archive re-analysis (`shockbench reanalyse`, issue 18 item 6; issue 33): identify (and diagnose) every
recording of an archive on dask.distributed, resumably, into one result JSON per recording and analysis and
a summary table, or, from the database, into a stored run that `--compare` compares with another
(docs/archive.md).

- sources.py: what to analyse, a folder of recordings with their vehicle files or every recording stored in
  a database, and the digest of each input (a re-run skips what is done on unchanged input);
- task.py: what a Dask worker runs for a batch of recordings shipped as bytes (service.analysis, as the
  commands), and the worker's set-up (one BLAS thread, the estimator loaded; worker_setup.py);
- results.py: the result files (written atomically) and the summary table DIR/summary.csv;
- run.py: the client: a LocalCluster or a scheduler by address, batches, the run stored;
- progress.py: the bar on a terminal, the lines elsewhere, the dashboard's address;
- archive.py: `shockbench archive import/export`;
- compare.py: `reanalyse --compare`, what a new version changes.

Must not import service.cli (the command runs the re-analysis, not the other way round), service.api nor
simulators.
"""
