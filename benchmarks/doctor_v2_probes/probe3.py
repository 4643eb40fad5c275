"""Probe 3: first forward-selection step of force families by HAC Wald tests, base curve with low-speed knots."""
import json
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy.stats import chi2

CACHE = "/tmp/foreign-dev-cache"
ALPHA = 0.05

def one(args):
    label, index = args
    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle
    from estimator.doctor import model as M
    from estimator.doctor.columns import interval_mean, with_columns
    from estimator.dynamics import coulomb_sign
    from estimator.identify import IdentifyOptions, identify
    from estimator.uncertainty import confidence_intervals
    from estimator.vehicle import TyreModel
    from simulators.foreign.manifest import draw_files, namespace_entropy
    truth = draw_files("dev", namespace_entropy("dev"), label, index, CACHE)
    rec, veh = read_recording_csv(truth["csv"]), read_vehicle(truth["toml"])
    if veh.unknown:
        veh = identify(rec, veh, IdentifyOptions(output_error=False)).model.vehicle
    pts = 15 if veh.is_axle else 30
    ref = M.Reference.of(rec, veh, M.FitSettings(pts, 5000, low_speed_knots=True))
    s0 = M.starting_structure(TyreModel.MAXWELL)
    m0 = M.fit(ref, s0)
    sig = m0.signals
    fam = {}
    def hinge_cols():
        cols = {}
        z = [c.spring_deflection_m for c in sig.corners]
        peak_pos = max(float(np.quantile(x, 0.999)) for x in z)
        peak_neg = min(float(np.quantile(x, 0.001)) for x in z)
        cols["rate"] = sig.suspension_column(z)
        for f in (0.4, 0.7):
            kp, kn = f * peak_pos, f * peak_neg
            cols[f"up{f}"] = sig.suspension_column([np.maximum(x - kp, 0) for x in z])
            cols[f"dn{f}"] = sig.suspension_column([np.minimum(x - kn, 0) for x in z])
        return cols
    fam["spring_curve"] = hinge_cols()
    fam["tyre_stiffness"] = {"tyre": sig.tyre_column([c.tyre_deflection_m for c in sig.corners])}
    vs = 0.005
    fam["low_speed_friction"] = {
        "step": sig.suspension_column([interval_mean(coulomb_sign, c.velocity_m_s) for c in sig.corners]),
        "peak": sig.suspension_column([interval_mean(lambda v: coulomb_sign(v) * np.exp(-(v / vs) ** 2), c.velocity_m_s) for c in sig.corners]),
    }
    res = {}
    for name, cols in fam.items():
        system = with_columns(m0.system, cols, m0.system.offset)
        theta, obj = M._solve(system, np.zeros((0, system.n_params)), M._initial(system, m0))
        ci = confidence_intervals(system, theta, rec.sample_time_s)
        idx = list(range(m0.system.n_params, system.n_params))
        th = theta[idx]; V = ci.covariance[np.ix_(idx, idx)]
        W = float(th @ np.linalg.lstsq(V, th, rcond=None)[0])
        p = float(chi2.sf(W, len(idx)))
        res[name] = dict(W=round(W, 1), q=len(idx), p=float(f"{p:.2g}"), obj=round(obj / m0.objective, 4))
    m = len(fam)
    best = min(res, key=lambda n: res[n]["p"])
    chosen = best if res[best]["p"] <= ALPHA / m else None
    return {"label": label, "i": index, "sizes": [round(float(e["size"]), 3) for e in truth["effects"]], "effects": [e["effect"] for e in truth["effects"]], "chosen": chosen, "res": res}

if __name__ == "__main__":
    labels = sys.argv[1].split(","); n = int(sys.argv[2])
    with ProcessPoolExecutor(2) as p:
        for r in p.map(one, [(l, i) for l in labels for i in range(n)]):
            print(json.dumps(r), flush=True)
