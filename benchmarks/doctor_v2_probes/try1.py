import sys
import time

sys.path.insert(0, '/work/doctor-v2')
from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import read_vehicle
from estimator.doctor import DiagnoseOptions, diagnose
from simulators.foreign.manifest import draw_files, namespace_entropy

label, index = sys.argv[1], int(sys.argv[2])
truth = draw_files("dev", namespace_entropy("dev"), label, index, "/tmp/foreign-dev-cache")
rec, veh = read_recording_csv(truth["csv"]), read_vehicle(truth["toml"])
t = time.perf_counter()
r = diagnose(rec, veh, DiagnoseOptions())
print(label, index, [e["effect"] for e in truth["effects"]], [round(float(e["size"]),3) for e in truth["effects"]], f"{time.perf_counter()-t:.1f}s")
print(r.conclusion)
for rnd in r.rounds:
    for c in sorted(rnd, key=lambda c: c.p_value)[:30]:
        print(f"   {c.effect:32s} W={c.equation_statistic:9.1f} LR={c.simulation_statistic:9.1f} q={c.unknowns} p_eq={c.equation_p:.2g} p_sim={c.simulation_p:.2g} gap={c.gap_ratio} {c.verdict}")
    print("   --")
print("GOF", r.p_value, r.gap_after_m)
