"""The science core: bench models, the objective of the paper, solvers, curve fitting, inspection figures.

Pure numpy/scipy. Nothing here does I/O or imports daq/, drivers/, service/ or simulators/.
"""
