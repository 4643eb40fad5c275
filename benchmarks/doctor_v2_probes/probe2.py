"""Probe 2: with low-speed knots in the base curve, the friction step column's Wald statistic and gap."""
import json
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

CACHE = "/tmp/foreign-dev-cache"

def one(args):
    label, index = args
    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle
    from estimator.doctor import model as M
    from estimator.doctor.catalog import EffectInstance, EffectName
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
    out = {"label": label, "i": index, "sizes": [round(float(e["size"]), 3) for e in truth["effects"]], "dt": rec.sample_time_s}
    for knots in (False, True):
        ref = M.Reference.of(rec, veh, M.FitSettings(pts, 5000, low_speed_knots=knots))
        s0 = M.starting_structure(TyreModel.MAXWELL)
        m0 = M.fit(ref, s0)
        sf = s0.with_effect(EffectInstance(EffectName.COULOMB_FRICTION))
        system, signals, air = M._build(ref, sf, M.ChannelCorrections(), None, (0.0, 0.0, 0.0), free_grid=True)
        theta, obj = M._solve(system, np.zeros((0, system.n_params)), None)
        mf = M.FittedModel(sf, veh, theta, system, signals, {}, [], obj)
        ci = confidence_intervals(system, theta, rec.sample_time_s)
        k = system.parameter_names.index("coulomb_friction_N")
        W = float(theta[k] ** 2 / ci.covariance[k, k])
        g = simulate_models([m0, mf], rec).gap_m()
        out["knots" if knots else "plain"] = dict(F=round(float(theta[k]), 1), W=round(W, 1), obj=round(obj / m0.objective, 4), gap0=round(float(g[0]) * 1e6, 1), gapratio=round(float(g[1] / g[0]), 3))
    return out

if __name__ == "__main__":
    labels = sys.argv[1].split(","); n = int(sys.argv[2])
    with ProcessPoolExecutor(2) as p:
        for r in p.map(one, [(l, i) for l in labels for i in range(n)]):
            print(json.dumps(r), flush=True)
