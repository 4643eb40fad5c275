"""Diagnose DEV draws with the v2 doctor; one line per draw."""
import json
import sys
import time

sys.path.insert(0, '/work/doctor-v2')
from concurrent.futures import ProcessPoolExecutor


def one(args):
    label, index, points = args
    sys.path.insert(0, '/work/doctor-v2')
    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle
    from estimator.doctor import DiagnoseOptions, diagnose
    from simulators.foreign.manifest import draw_files, namespace_entropy
    truth = draw_files("dev", namespace_entropy("dev"), label, index, "/tmp/foreign-dev-cache")
    rec, veh = read_recording_csv(truth["csv"]), read_vehicle(truth["toml"])
    t = time.perf_counter()
    opts = DiagnoseOptions(workers=1) if points is None else DiagnoseOptions(workers=1, points=points * (1 if not veh.is_axle else 1) // (2 if veh.is_axle else 1))
    r = diagnose(rec, veh, opts)
    top = sorted(r.rounds[-1], key=lambda c: c.p_value)[:2] if r.rounds else []
    return dict(label=label, i=index, truth=[(e["effect"], round(float(e["size"]), 3)) for e in truth["effects"]],
                named=r.effects_named, unexplained=r.unexplained, p=float(f"{r.p_value:.2g}"),
                gap=[round(r.gap_before_m * 1e6, 1), round(r.gap_after_m * 1e6, 1), round(r.expected_gap_m * 1e6, 1)],
                s=round(time.perf_counter() - t, 1),
                last=[(c.effect, round(c.equation_statistic, 1), round(c.simulation_statistic, 1), c.unknowns, float(f"{c.p_value:.2g}")) for c in top])
if __name__ == "__main__":
    labels = sys.argv[1].split(","); idx = [int(x) for x in sys.argv[2].split(",")]
    points = int(sys.argv[3]) if len(sys.argv) > 3 else None
    with ProcessPoolExecutor(int(__import__("os").environ.get("JOBS", "2"))) as p:
        for r in p.map(one, [(l, i, points) for l in labels for i in idx]):
            print(json.dumps(r), flush=True)
