"""A world the model doctor's catalogue did not make (issue 29, item 4): recordings of a quarter car corner
(car, van, motorcycle sizes) and a car front axle on the plate, whose hidden effects take forms unlike the
catalogue's (k3·ζ³, F·tanh(v/band), pure delays): Stribeck and LuGre/Dahl friction, bump stops with
clearance, first-order and moving-average sensor filters, gain errors, dampers whose force lags, asymmetric
axles, wrong stated rates, an unrecorded force; 500 Hz and 1 kHz; white, AR(1) and 1/f-like noise.

It integrates its own equations with scipy's solve_ivp and reuses from simulators/independent only generic
pieces: the vehicle parameter draws, the chirp, the real-table dampers, the WorldRecording container and the
file writer. It imports nothing from estimator/, drivers/, daq/ or service/.

- effects.py: the effect laws; physics.py: the equations of motion; sensors.py: the laser channels;
- world.py: simulate a sweep and measure the force effects' sizes;
- draws.py: classes, random draws by namespace (DEV, HELD-OUT) and the truth record;
- manifest.py: freezing the held-out draws (benchmarks/heldout/manifest.json) and verifying them.


Must not import estimator, drivers, daq or service (it would share their mistakes)."""
