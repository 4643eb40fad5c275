"""Probe 4: Wald statistics scaled by their parametric-bootstrap mean (a calibrated chi-square)."""
import json
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy.stats import chi2

CACHE = "/tmp/foreign-dev-cache"
ALPHA = 0.05
B = 6

def walds(rec, veh, pts, warm=None):
    from estimator.doctor import model as M
    from estimator.doctor.columns import interval_mean, with_columns
    from estimator.dynamics import coulomb_sign
    from estimator.uncertainty import confidence_intervals
    from estimator.vehicle import TyreModel
    ref = M.Reference.of(rec, veh, M.FitSettings(pts, 5000, low_speed_knots=True))
    m0 = M.fit(ref, M.starting_structure(TyreModel.MAXWELL), warm=warm)
    sig = m0.signals
    z = [c.spring_deflection_m for c in sig.corners]
    peak_pos = max(float(np.quantile(x, 0.999)) for x in z); peak_neg = min(float(np.quantile(x, 0.001)) for x in z)
    spring = {"rate": sig.suspension_column(z)}
    for f in (0.4, 0.7):
        spring[f"up{f}"] = sig.suspension_column([np.maximum(x - f * peak_pos, 0) for x in z])
        spring[f"dn{f}"] = sig.suspension_column([np.minimum(x - f * peak_neg, 0) for x in z])
    vs = 0.005
    fam = {"spring_curve": spring,
           "tyre_stiffness": {"tyre": sig.tyre_column([c.tyre_deflection_m for c in sig.corners])},
           "low_speed_friction": {
               "step": sig.suspension_column([interval_mean(coulomb_sign, c.velocity_m_s) for c in sig.corners]),
               "peak": sig.suspension_column([interval_mean(lambda v: coulomb_sign(v) * np.exp(-(v / vs) ** 2), c.velocity_m_s) for c in sig.corners])}}
    out = {}
    for name, cols in fam.items():
        system = with_columns(m0.system, cols, m0.system.offset)
        theta, obj = M._solve(system, np.zeros((0, system.n_params)), M._initial(system, m0))
        ci = confidence_intervals(system, theta, rec.sample_time_s)
        idx = list(range(m0.system.n_params, system.n_params))
        th = theta[idx]; V = ci.covariance[np.ix_(idx, idx)]
        out[name] = (float(th @ np.linalg.lstsq(V, th, rcond=None)[0]), len(idx))
    return out, m0, ref

def one(args):
    label, index = args
    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle
    from estimator.doctor.expected import plausible_truth, synthetic_recording
    from estimator.doctor.noise import measure_noise
    from estimator.doctor.simulation import simulate_models
    from estimator.identify import IdentifyOptions, identify
    from simulators.foreign.manifest import draw_files, namespace_entropy
    truth = draw_files("dev", namespace_entropy("dev"), label, index, CACHE)
    rec, veh = read_recording_csv(truth["csv"]), read_vehicle(truth["toml"])
    if veh.unknown:
        veh = identify(rec, veh, IdentifyOptions(output_error=False)).model.vehicle
    pts = 15 if veh.is_axle else 30
    observed, m0, ref = walds(rec, veh, pts)
    sim = simulate_models([m0], rec)
    settings = ref.settings
    truthm = plausible_truth(m0, rec, settings)
    tsim = simulate_models([truthm], rec)
    measured = {n: rec.channels[n] for n in sim.residual}
    resid = {n: r[:, 0] for n, r in sim.residual.items()}
    noise = measure_noise(resid, measured, rec.sample_time_s, ref.filters.excitation_top_Hz)
    pred = {n: p[:, 0] for n, p in tsim.predicted.items()}
    boot = {k: [] for k in observed}
    for b in range(B):
        syn = synthetic_recording(rec, pred, noise, b)
        w, _, _ = walds(syn, veh, pts, warm=m0)
        for k in w: boot[k].append(w[k][0])
    res = {}
    for k, (W, q) in observed.items():
        lam = max(1.0, float(np.mean(boot[k])) / q)
        res[k] = dict(W=round(W, 1), q=q, lam=round(lam, 2), p=float(f"{chi2.sf(W / lam, q):.2g}"))
    best = min(res, key=lambda n: res[n]["p"])
    chosen = best if res[best]["p"] <= ALPHA / len(res) else None
    return {"label": label, "i": index, "sizes": [round(float(e["size"]), 3) for e in truth["effects"]], "chosen": chosen, "res": res}

if __name__ == "__main__":
    labels = sys.argv[1].split(","); n = int(sys.argv[2])
    with ProcessPoolExecutor(2) as p:
        for r in p.map(one, [(l, i) for l in labels for i in range(n)]):
            print(json.dumps(r), flush=True)
