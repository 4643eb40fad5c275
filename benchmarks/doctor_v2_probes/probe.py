"""Probe: Wald statistics of today's force candidates on dev draws of the foreign world."""
import json
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

CACHE = "/tmp/foreign-dev-cache"

def one(args):
    label, index = args
    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle
    from estimator.doctor.catalog import EffectInstance, EffectName
    from estimator.doctor.fitting import fit
    from estimator.doctor.model import FitSettings, Reference, starting_structure
    from estimator.doctor.simulation import simulate_models
    from estimator.identify import IdentifyOptions, identify
    from estimator.uncertainty import confidence_intervals
    from estimator.vehicle import TyreModel
    from simulators.foreign.manifest import draw_files, namespace_entropy
    truth = draw_files("dev", namespace_entropy("dev"), label, index, CACHE)
    rec, veh = read_recording_csv(truth["csv"]), read_vehicle(truth["toml"])
    if veh.unknown:
        veh = identify(rec, veh, IdentifyOptions(output_error=False)).model.vehicle
    pts = 15 if veh.is_axle else 30
    ref = Reference.of(rec, veh, FitSettings(pts, 5000))
    s0 = starting_structure(TyreModel.MAXWELL)
    m0 = fit(ref, s0)
    out = {"label": label, "i": index, "effects": [e["effect"] for e in truth["effects"]],
           "sizes": [round(float(e["size"]), 4) for e in truth["effects"]], "dt": rec.sample_time_s}
    names = [EffectName.SPRING_STIFFNESS, EffectName.TYRE_STIFFNESS, EffectName.COULOMB_FRICTION,
             EffectName.PROGRESSIVE_SPRING, EffectName.TYRE_DAMPING]
    models = [m0]
    stats = {}
    for n in names:
        inst = EffectInstance(n)
        m = fit(ref, s0.with_effect(inst))
        base = m.constrained if m.constrained is not None else m
        new = [k for k in base.system.parameter_names if k not in m0.system.parameter_names]
        ci = confidence_intervals(base.system, base.theta, rec.sample_time_s)
        idx = [base.system.parameter_names.index(k) for k in new]
        th = base.theta[idx]; V = ci.covariance[np.ix_(idx, idx)]
        W = float(th @ np.linalg.solve(V, th))
        stats[n.value] = [round(W, 1), round(m.objective / m0.objective, 4)]
        models.append(m)
    gaps = simulate_models(models, rec).gap_m()
    for k, n in enumerate(names):
        stats[n.value].append(round(float(gaps[k + 1] / gaps[0]), 3))
    out["gap0_um"] = round(float(gaps[0]) * 1e6, 1)
    out["stats"] = stats
    return out

if __name__ == "__main__":
    labels = sys.argv[1].split(",")
    n = int(sys.argv[2])
    jobs = [(l, i) for l in labels for i in range(n)]
    with ProcessPoolExecutor(2) as p:
        for r in p.map(one, jobs):
            print(json.dumps(r), flush=True)
