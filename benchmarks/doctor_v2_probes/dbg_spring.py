import sys

sys.path.insert(0, '/work/doctor-v2')
from dataclasses import replace

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import read_vehicle
from estimator.doctor.catalog import EffectInstance, EffectName
from estimator.doctor.fitting import fit
from estimator.doctor.model import FitSettings, Reference, starting_structure
from estimator.doctor.parameters import report
from estimator.doctor.simulation import simulate_models
from estimator.vehicle import TyreModel
from simulators.foreign.manifest import draw_files, namespace_entropy

label, index = sys.argv[1], int(sys.argv[2])
truth = draw_files("dev", namespace_entropy("dev"), label, index, "/tmp/foreign-dev-cache")
rec, veh = read_recording_csv(truth["csv"]), read_vehicle(truth["toml"])
print(truth["effects"], veh.spring_stiffness_N_per_m)
ref = Reference.of(rec, veh, FitSettings(15 if veh.is_axle else 30, 5000))
s0 = starting_structure(TyreModel.MAXWELL)
m0 = fit(ref, s0)
m1 = fit(ref, s0.with_effect(EffectInstance(EffectName.SPRING_CURVE)), warm=m0)
print("knots", ref.knots_m)
print(report(EffectInstance(EffectName.SPRING_CURVE), m1))
print("mass", m0.sprung_mass_kg, m1.sprung_mass_kg)
names = m1.system.parameter_names
lin = m1.theta.copy()
for k, n in enumerate(names):
    if n.startswith("spring_hinge"):
        lin[k] = 0.0
m_lin = replace(m1, theta=lin)
g = simulate_models([m0, m1, m_lin], rec).gap_m()
print("gaps um", g * 1e6)
