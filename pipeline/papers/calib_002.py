"""Study calib-002: structural parameter identification of an articulated-arm CMM (papers/002).

``python -m pipeline study calib-002 [--seeds 20] [--quick]``; about 30 s with the defaults on the
shared 2-core machine (measured with 5 other workers running; ``--quick`` about 5 s).

The paper (``002_2f409157c2a376aa.txt``): a 6-axis AACMM in standard Denavit-Hartenberg form,
``T_i = Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`` (§2.1 eq. 1), probe tip at ``(0, 0, l)`` of
the last frame (eq. 2): 6 x 4 + 1 = 25 structural parameters. §3.3: the SVD of the stacked
identification Jacobian has rank 23, so two parameters are linearly related to two others and are
not identified; §3.4: least squares on the 23 columns (eq. 18), one iteration suffices; §4: 200
poses before (Table 2: max 1.485 / 1.366 / -0.978 mm, mean |e| 0.524 / 0.545 / 0.421 mm per axis),
50 identification poses (Table 3), another 200 poses after (Table 4: max -0.112 / 0.116 / 0.117 mm,
mean |e| 0.036 / 0.038 / 0.044 mm). Its Table 1 (nominal DH values) and Table 3 (identified values)
and the names of the coupled parameters were lost in the text extraction.

What is estimated and why. The arm's DH table is the one published for a 6-axis AACMM of the same
2-2-2 layout (alternating swivel and hinge joints, all adjacent axes perpendicular as the paper
states): Hindawi Mathematical Problems in Engineering 2018, article 1760190, "A Novel Kinematic
Parameters Identification Method for Articulated Arm Coordinate Measuring Machines Using
Repeatability and Scaling Factor", Table 2 (identified values; rounded here to nominal:
alpha = -90, -90, 90, -90, 90, -90 deg; a2 = a4 = 62.1 mm; d1 = 376.5, d3 = 750.7, d5 = 500.6,
d6 = 15.07 mm; probe l = 97.8 mm). The truth's deviation from the nominal table is not known from
the paper: its size is scaled so that the mean "before" error over the seeds equals Table 2's mean
(an input, stated as such); the reading noise is the AACMM's stated point repeatability 0.05 mm
(1 sigma per axis, §4), the paper's reference instrument being unnamed.
"""

from __future__ import annotations

import argparse
import math
import time

import casadi as ca
import numpy as np

from pipeline.calibration import error_model as em
from pipeline.papers.registry import save_result

_DEG = math.pi / 180.0
#: (theta offset rad, d m, a m, alpha rad) per joint: MPE 2018 / 1760190 Table 2, rounded (docstring)
AACMM_DH = [(0.0, 0.3765, 0.0, -90 * _DEG), (0.0, 0.0, 0.0621, -90 * _DEG), (0.0, 0.7507, 0.0, 90 * _DEG),
            (0.0, 0.0, 0.0621, -90 * _DEG), (0.0, 0.5006, 0.0, 90 * _DEG), (0.0, 0.01507, 0.0, -90 * _DEG)]
AACMM_PROBE_M = 0.0978
#: paper 002 Tables 2 and 4 (per axis x, y, z; mm) and §3.3
PAPER_002 = {"rank": 23, "redundant": 2, "n_identification": 50, "n_validation": 200,
             "before_max_mm": (1.485, 1.366, -0.978), "before_mean_abs_mm": (0.524, 0.545, 0.421),
             "after_max_mm": (-0.112, 0.116, 0.117), "after_mean_abs_mm": (0.036, 0.038, 0.044)}
#: AACMM point repeatability (paper 002 §4), taken as the 1-sigma per-axis reading noise
REPEATABILITY_M = 0.05e-3


def parameter_names(n_joints: int = 6) -> list[str]:
    return [f"{k}{i + 1}" for i in range(n_joints) for k in ("theta", "d", "a", "alpha")] + ["l"]


def nominal_parameters(table: list[tuple[float, float, float, float]] | None = None,
                       probe_m: float = AACMM_PROBE_M) -> np.ndarray:
    rows = AACMM_DH if table is None else table
    return np.array([v for row in rows for v in row] + [probe_m])


def dh_probe_function(n_joints: int = 6) -> ca.Function:
    """``(q, params) -> (p (3), dp/dparams (3 x 4n+1))`` of the DH arm with a probe (docstring)."""
    q = ca.SX.sym("q", n_joints)
    prm = ca.SX.sym("p", 4 * n_joints + 1)
    T = ca.SX.eye(4)
    for i in range(n_joints):
        th, d, a, al = prm[4 * i], prm[4 * i + 1], prm[4 * i + 2], prm[4 * i + 3]
        c, s = ca.cos(th + q[i]), ca.sin(th + q[i])
        cal, sal = ca.cos(al), ca.sin(al)
        A = ca.vertcat(ca.horzcat(c, -s * cal, s * sal, a * c), ca.horzcat(s, c * cal, -c * sal, a * s),
                       ca.horzcat(0, sal, cal, d), ca.horzcat(0, 0, 0, 1))
        T = T @ A
    p = (T @ ca.vertcat(0, 0, prm[4 * n_joints], 1))[:3]
    return ca.Function("dh_probe", [q, prm], [p, ca.jacobian(p, prm)])


class ProbeModel:
    """Batched probe positions and identification Jacobians (CasADi ``map``)."""

    def __init__(self, n_joints: int = 6) -> None:
        self.f = dh_probe_function(n_joints)
        self.n = 4 * n_joints + 1
        self._maps: dict[int, ca.Function] = {}

    def __call__(self, Q: np.ndarray, prm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (N, 3) and Jacobian blocks (N, 3, n)."""
        N = len(Q)
        if N not in self._maps:
            self._maps[N] = self.f.map(N)
        p, J = self._maps[N](np.asarray(Q, float).T, prm)
        return np.asarray(p).T, np.asarray(J).reshape(3, N, self.n).transpose(1, 0, 2)


def identifiability(model: ProbeModel, nominal: np.ndarray, rng: np.random.Generator,
                    n_poses: int = 50) -> em.IdentifiabilityReport:
    """Paper 002 §3.3: rank and linearly related parameters from the SVD of the stacked Jacobian
    (parameters kept in the table's order: the later of a coupled pair is the redundant one)."""
    Q = rng.uniform(-np.pi, np.pi, (n_poses, 6))
    J = model(Q, nominal)[1].reshape(-1, model.n)
    return em.identifiability(J, parameter_names(), order=list(range(model.n)))


def _axis_stats(E: np.ndarray) -> dict:
    """Per axis: the error of largest magnitude (signed, as Tables 2 and 4) and the mean |e|."""
    i = np.argmax(np.abs(E), axis=0)
    return {"max_signed": E[i, [0, 1, 2]], "max_abs": np.abs(E).max(axis=0), "mean_abs": np.abs(E).mean(axis=0)}


def perturbation(rng: np.random.Generator, n: int, length_sigma_m: float, angle_sigma_rad: float) -> np.ndarray:
    """Gaussian deviations of the truth from the nominal table: lengths (d, a, l) and angles (theta, alpha)."""
    names = parameter_names()
    sig = np.array([length_sigma_m if nm[0] in "dal" and not nm.startswith("alpha") else angle_sigma_rad
                    for nm in names])
    return sig * rng.standard_normal(n)


def run_seed(seed: int, scale: float, noise_m: float, n_id: int = 50, n_val: int = 200, iterations: int = 3,
             start_offset: tuple[float, float] = (0.0, 0.0), model: ProbeModel | None = None,
             noise_shape: str = "gaussian") -> dict:
    """One simulated AACMM: truth = nominal + ``scale`` x (1 mm, 1 mrad) Gaussian deviations; Gauss-Newton
    steps of paper 002 eq. 18 on the 23 identifiable columns from the nominal table (or from a start
    ``start_offset`` = (m, rad) further away: §1 claim that precise initial values are not needed).
    Reading noise per axis: Gaussian with sigma ``noise_m``, or (``noise_shape="uniform"``) bounded,
    uniform on ±sqrt(3) ``noise_m`` (the same sigma, no tails: the bounded-noise experiment)."""
    model = model or ProbeModel()
    rng = np.random.default_rng([seed, 2])
    nominal = nominal_parameters()
    rep = identifiability(model, nominal, rng)
    cols = rep.identifiable
    true = nominal + scale * perturbation(rng, model.n, 1e-3, 1e-3)

    def measure(Q: np.ndarray) -> np.ndarray:
        if noise_shape == "uniform":
            return model(Q, true)[0] + noise_m * math.sqrt(3.0) * rng.uniform(-1.0, 1.0, (len(Q), 3))
        return model(Q, true)[0] + noise_m * rng.standard_normal((len(Q), 3))

    Q_before, Q_id, Q_after = (rng.uniform(-np.pi, np.pi, (k, 6)) for k in (n_val, n_id, n_val))
    Y_before, Y_id, Y_after = measure(Q_before), measure(Q_id), measure(Q_after)
    before = _axis_stats(Y_before - model(Q_before, nominal)[0])
    prm = nominal + perturbation(rng, model.n, *start_offset)
    history = []
    for it in range(iterations + 1):
        after = _axis_stats(Y_after - model(Q_after, prm)[0])
        history.append({"iteration": it, "mean_abs_m": after["mean_abs"], "max_abs_m": after["max_abs"]})
        if it == iterations:
            break
        P, J = model(Q_id, prm)
        d, *_ = np.linalg.lstsq(J.reshape(-1, model.n)[:, cols], (Y_id - P).ravel(), rcond=None)
        prm = prm.copy()
        prm[cols] += d
    return {"seed": seed, "rank": rep.rank, "combined": rep.as_dict()["combined"], "before": before,
            "after": after, "history": history, "nominal": nominal, "true": true, "estimate": prm,
            "identified": cols}


def _mse(values: list[float]) -> tuple[float, float]:
    v = np.asarray(values, float)
    return float(v.mean()), float(v.std(ddof=1) / math.sqrt(len(v))) if len(v) > 1 else 0.0


def _fmt(values: list[float], k: float = 1e3, digits: int = 3) -> str:
    m, s = _mse(values)
    return f"{k * m:.{digits}f} ± {k * s:.{digits}f}"


def fitted_scale(seeds: list[int], noise_m: float, model: ProbeModel, noise_shape: str = "gaussian") -> float:
    """Truth deviation scale whose mean 'before' error over ``seeds`` equals Table 2's mean (docstring)."""
    unit = [run_seed(s, 1.0, noise_m, iterations=0, model=model, noise_shape=noise_shape)["before"]["mean_abs"].mean()
            for s in seeds]
    target = float(np.mean(PAPER_002["before_mean_abs_mm"])) * 1e-3
    # before = |deviation effect + noise|: remove the noise share in quadrature (Gaussian per axis)
    noise_abs = noise_m * math.sqrt(2 / math.pi)
    return math.sqrt(max(target ** 2 - noise_abs ** 2, 0.0)) / math.sqrt(max(np.mean(unit) ** 2 - noise_abs ** 2,
                                                                             1e-30))


def _print_axes(title: str, rows: list[dict], key: str, paper_max: tuple, paper_mean: tuple) -> dict:
    print(f"\n{title}")
    print("| axis | max |e| ours [mm] | paper max [mm] | mean |e| ours [mm] | paper mean |e| [mm] |")
    print("|---|---|---|---|---|")
    out = {}
    for a, ax in enumerate("xyz"):
        mx = [r[key]["max_abs"][a] for r in rows]
        mn = [r[key]["mean_abs"][a] for r in rows]
        out[ax] = {"max_abs_mm": [1e3 * v for v in _mse(mx)], "mean_abs_mm": [1e3 * v for v in _mse(mn)]}
        print(f"| {ax} | {_fmt(mx)} | {paper_max[a]} | {_fmt(mn)} | {paper_mean[a]} |")
    return out


def study_002(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="study calib-002")
    ap.add_argument("--seeds", type=int, default=20, help="number of simulated arms (seeds 0..n-1)")
    ap.add_argument("--noise-mm", type=float, default=1e3 * REPEATABILITY_M, help="reading noise, 1 sigma per axis")
    ap.add_argument("--noise-shape", choices=["gaussian", "uniform"], default="gaussian",
                    help="reading noise per axis: Gaussian, or bounded (uniform, same sigma)")
    ap.add_argument("--quick", action="store_true", help="5 seeds, no sweeps")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    seeds = list(range(5 if a.quick else a.seeds))
    noise = a.noise_mm * 1e-3
    model = ProbeModel()
    result: dict = {"args": vars(a), "paper": PAPER_002}

    # E1: the paper's rank and couplings, and the probe-on-axis-6 table (why an invented a6 = 0 drops the rank)
    rep = identifiability(model, nominal_parameters(), np.random.default_rng([0, 2]))
    print(f"\npaper 002 §3.3: SVD of the 150 x 25 identification Jacobian (50 poses), DH table of MPE 2018/1760190:\n"
          f"  rank {rep.rank} (paper 23), redundant {25 - rep.rank} (paper 2: names lost in the text extraction)")
    for k, v in rep.combined.items():
        print(f"  {k} is linearly related with " + ", ".join(f"{n} (coefficient {c:+.4g})" for n, c in v)
              + f" -> {k} not identified")
    on_axis = [row for row in AACMM_DH[:5]] + [(0.0, 0.01507, 0.0, 0.0)]
    rep_axis = identifiability(model, nominal_parameters(on_axis), np.random.default_rng([0, 2]))
    print(f"  experiment 'probe on axis 6' (alpha6 = 0, a6 = 0: joint 6 no longer moves the tip): rank {rep_axis.rank}")
    result["rank"] = rep.rank
    result["combined"] = rep.as_dict()["combined"]
    result["rank_probe_on_axis"] = rep_axis.rank

    # E2: Tables 2 and 4 over the seeds
    scale = fitted_scale(seeds, noise, model, a.noise_shape)
    rows = [run_seed(s, scale, noise, model=model, noise_shape=a.noise_shape) for s in seeds]
    print(f"\ntruth deviations: {scale:.3f} mm / {scale:.3f} mrad (1 sigma per DH parameter), fitted so that the mean "
          f"'before' error equals Table 2's; reading noise {a.noise_mm:.3f} mm per axis; {len(seeds)} seeds, "
          "mean ± standard error")
    result["scale_mm_mrad"] = scale
    result["table2"] = _print_axes("Table 2 (200 poses, nominal DH table):", rows, "before",
                                   PAPER_002["before_max_mm"], PAPER_002["before_mean_abs_mm"])
    result["table4"] = _print_axes("Table 4 (another 200 poses, after 3 least-squares iterations on 50 poses):", rows,
                                   "after", PAPER_002["after_max_mm"], PAPER_002["after_mean_abs_mm"])
    print("\nGauss-Newton iterations (paper: 'results reached just after one time iteration', no benefit after):")
    print("| iteration | mean |e| over axes [mm] | max |e| over axes [mm] |")
    print("|---|---|---|")
    result["iterations"] = []
    for it in range(len(rows[0]["history"])):
        mn = [float(r["history"][it]["mean_abs_m"].mean()) for r in rows]
        mx = [float(r["history"][it]["max_abs_m"].max()) for r in rows]
        result["iterations"].append({"iteration": it, "mean_abs_mm": _mse(mn)[0] * 1e3,
                                     "max_abs_mm": _mse(mx)[0] * 1e3})
        print(f"| {it} | {_fmt(mn, digits=4)} | {_fmt(mx, digits=4)} |")

    # Table 3 counterpart: nominal, truth and estimate of seed 0 and the estimation error over the seeds
    names = parameter_names()
    err = np.array([r["estimate"] - r["true"] for r in rows])
    r0 = rows[0]
    print("\nTable 3 counterpart (paper's identified values not in the text; ours: seed 0 and the RMS estimation error "
          "over the seeds; lengths mm, angles deg)")
    print("| parameter | nominal | truth (seed 0) | estimate (seed 0) | RMS error over seeds | identified |")
    print("|---|---|---|---|---|---|")
    table3 = []
    for i, nm in enumerate(names):
        k = 1e3 if (nm[0] in "dal" and not nm.startswith("alpha")) else 180 / math.pi
        rms = float(np.sqrt(np.mean(err[:, i] ** 2)))
        ident = i in r0["identified"]
        table3.append({"name": nm, "nominal": r0["nominal"][i], "true": r0["true"][i], "estimate": r0["estimate"][i],
                       "rms_error": rms, "identified": ident})
        print(f"| {nm} | {k * r0['nominal'][i]:.4f} | {k * r0['true'][i]:.4f} | {k * r0['estimate'][i]:.4f} | "
              f"{k * rms:.4f} | {'yes' if ident else 'no (redundant, kept at nominal)'} |")
    result["table3"] = table3
    unchanged = [nm for i, nm in enumerate(names) if i not in r0["identified"]]
    print(f"parameters left at their nominal values: {', '.join(unchanged)} "
          "(paper: the redundant ones are 'not changed')")

    if not a.quick:
        # E3: reading noise vs the after level; E4: start far from the nominal table
        print("\nexperiment 'reading noise' (the after level is the noise floor: mean |e| = sigma sqrt(2/pi)):")
        print("| noise [mm, 1 sigma per axis] | mean |e| after [mm] | sigma sqrt(2/pi) [mm] |")
        print("|---|---|---|")
        result["noise_sweep"] = []
        for nz in (0.005e-3, 0.02e-3, 0.05e-3, 0.1e-3):
            rr = [run_seed(s, scale, nz, model=model, noise_shape=a.noise_shape) for s in seeds[:10]]
            mn = [float(r["after"]["mean_abs"].mean()) for r in rr]
            result["noise_sweep"].append({"noise_mm": nz * 1e3, "after_mean_abs_mm": _mse(mn)[0] * 1e3})
            print(f"| {nz * 1e3:.3f} | {_fmt(mn, digits=4)} | {nz * 1e3 * math.sqrt(2 / math.pi):.4f} |")
        print("\nexperiment 'number of identification poses' (paper §4: stable above 30 poses, almost invariant "
              "above 50):")
        print("| poses | mean |e| after [mm] | max |e| after [mm] |")
        print("|---|---|---|")
        result["poses_sweep"] = []
        for n_id in (10, 20, 30, 50, 100, 200):
            rr = [run_seed(s, scale, noise, n_id=n_id, model=model, noise_shape=a.noise_shape) for s in seeds[:10]]
            mn = [float(r["after"]["mean_abs"].mean()) for r in rr]
            mx = [float(r["after"]["max_abs"].max()) for r in rr]
            result["poses_sweep"].append({"poses": n_id, "after_mean_abs_mm": _mse(mn)[0] * 1e3,
                                          "after_max_abs_mm": _mse(mx)[0] * 1e3})
            print(f"| {n_id} | {_fmt(mn, digits=4)} | {_fmt(mx, digits=4)} |")
        print("\nexperiment 'imprecise initial parameters' (paper §1: initial values may be arbitrary 'as long as "
              "they are not too exaggerated'):")
        print("| start offset (1 sigma) | mean |e| after 1 / 2 / 5 iterations [mm] |")
        print("|---|---|")
        result["start_sweep"] = []
        for off in ((1e-3, 1e-3), (10e-3, 10e-3), (30e-3, 50e-3)):
            rr = [run_seed(s, scale, noise, iterations=5, start_offset=off, model=model, noise_shape=a.noise_shape)
                  for s in seeds[:10]]
            cells = [float(np.median([r["history"][it]["mean_abs_m"].mean() for r in rr])) for it in (1, 2, 5)]
            result["start_sweep"].append({"length_sigma_mm": off[0] * 1e3, "angle_sigma_mrad": off[1] * 1e3,
                                          "median_mean_abs_mm_after_1_2_5": [c * 1e3 for c in cells]})
            print(f"| {off[0] * 1e3:.0f} mm / {off[1] * 1e3:.0f} mrad | "
                  + " / ".join(f"{1e3 * c:.4f}" for c in cells) + " |")
    result["run_time_s"] = time.perf_counter() - t0
    print(f"\nrun time {result['run_time_s']:.1f} s")
    save_result("calib-002", result)
    return 0
