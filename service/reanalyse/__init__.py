"""Archive re-analysis (`shockbench reanalyse`, issue 18 item 6): identify (and diagnose) every recording of
an archive on dask.distributed, resumably, into one result JSON per recording and analysis and a summary
table.

- sources.py: what to analyse, a folder of recordings with their vehicle files or every stored sweep of a
  database, and the digest of each input (a re-run skips what is done on unchanged input);
- task.py: what a Dask worker runs for one recording and analysis (service.analysis, as the commands);
- results.py: the result files (written atomically) and the summary table DIR/summary.csv;
- run.py: the client: a LocalCluster or a scheduler by address, the progress lines, the run.
"""
