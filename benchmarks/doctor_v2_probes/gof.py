import sys

sys.path.insert(0, '/work/doctor-v2')
from simulators.foreign.manifest import draw_files, namespace_entropy
from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import read_vehicle
from estimator.doctor import DiagnoseOptions, diagnose
import importlib; D = importlib.import_module("estimator.doctor.diagnose")
orig = D._Doctor.bootstrap
def spy(self, final, simulated):
    o, g = orig(self, final, simulated)
    print("  final objective", final.objective, "boot", [round(x, 1) for x in o])
    print("  final gap", simulated.gap_m * 1e6, "boot", [round(x * 1e6, 1) for x in g])
    return o, g
D._Doctor.bootstrap = spy
for arg in sys.argv[1:]:
    label, index = arg.split(":")
    truth = draw_files("dev", namespace_entropy("dev"), label, int(index), "/tmp/foreign-dev-cache")
    rec, veh = read_recording_csv(truth["csv"]), read_vehicle(truth["toml"])
    r = diagnose(rec, veh, DiagnoseOptions(max_steps=0))
    print(arg, rec.sample_time_s, f"p={r.p_value:.2g} p_obj={r.p_objective:.2g} p_gap={r.p_gap:.2g}")
