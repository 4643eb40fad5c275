"""An independent test world for the estimator and the model doctor (issue 13).

Everything here is written from the equations of motion and shares no code with `estimator/` or
`simulators/vehicle_sim.py`: continuous-time integration by scipy's solve_ivp (DOP853, tight tolerances,
dense output sampled at the sample instants), a plate chirp given analytically, dampers as smooth monotone
interpolants of tables (real dyno data, a published table, an orifice-and-valve model), the Maxwell tyre as
its own differential equation, contact that cannot pull (lift-off), sensors with 1 µm quantisation and white
or AR(1) noise, and physical effects injected one or two at a time. It writes the project's recording CSV
and vehicle TOML itself (files.py), so that the only thing it has in common with the project is the format.

- excitation.py: the plate chirp and its analytic velocity;
- dampers.py: damper tables (realdata), the valve model, the smooth interpolant and its inverse;
- vehicles.py: the truth (masses, springs, tyre, damper, effects) and what the vehicle file states;
- physics.py: the right-hand sides of the quarter car and the axle;
- sensors.py: laser channels (delay, offset, noise, quantisation);
- world.py: simulate a sweep; files.py: write it; cases.py: random cases per effect class.


Must not import estimator, drivers, daq, service or the rest of simulators (it would share their
mistakes)."""
