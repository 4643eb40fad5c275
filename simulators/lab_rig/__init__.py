"""A laboratory quarter-car rig as a test world (issue 29, item 5): a light rig of a few kilograms whose
data sheet states its spring and tyre rates 40-80% off, with a force between body and wheel that no file
records (an active-suspension voice coil run by the lab's controller, its cogging, its cable's drag) and
friction of its own, sampled at 500 Hz by laser-like channels.

Written from the equations of motion; it imports nothing from estimator/, drivers/, daq/ or service/ and
shares no effect law with the estimator. From the independent world (simulators/independent) it reuses
the generic pieces only: the chirp, the laser noise and quantisation, and the file writer.

- rig.py: the truth (masses, springs, tyre pad, damper, coil, cable, bearings) and what its file states;
- signals.py: multisines, smooth steps and bumps (the plate's runs and the coil's command);
- physics.py: the right-hand side, in absolute heights with gravity;
- world.py: a run simulated, read by the lasers and written; draws.py: random rigs and their runs.


Must not import estimator, drivers, daq or service (it would share their mistakes)."""
