"""Imported by the local cluster's forkserver (service.reanalyse.forkserver.PRELOAD): an analysis's modules
and one BLAS thread set up once, in the server, so that every worker forked from it starts warm. Importing
this module is its only use: the forkserver preloads modules by name."""

from service.reanalyse.task import warm_up

warm_up()
