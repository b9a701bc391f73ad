"""Identification on the real Stäubli TX40 record (``data/staubli_tx40/``, FIGAROH examples,
Apache-2.0; facts from its README).

Steps (paper ``004_abbe750b8bbcc3aa.txt`` §4.1 on a real robot):

1. motor positions/torques -> joint side with the gear matrix of ``robots/staubli_tx40/robot.yaml``
   (``q = K^-1 q_motor``, ``tau = K^T tau_motor``, K[5,4] = N6 couples axes 5 and 6), joint
   offsets ``q2 -= pi/2``, ``q3 += pi/2`` (README);
2. zero-phase Butterworth low-pass of the positions (100 Hz), central differences to velocity and
   acceleration, parallel decimation of states and torques by 10 (5 kHz -> 500 Hz), border
   samples dropped;
3. base parameters (pivoted QR), OLS on all samples -> the reference figures of the README
   (58 base parameters, condition number ~970, RMS ~3.35 N m);
4. held-out test: fit on the first ``train_fraction`` of the record, score on the rest, for OLS,
   Gautier's WLS and the physically consistent fit (log-Cholesky, positive rotor inertia and
   friction).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.core.blas import single_thread_blas
from pipeline.core.config import REPO_ROOT
from pipeline.core.errors import ConfigError, DataFileError
from pipeline.identification import estimate as est_mod
from pipeline.identification.config import TX40_SAMPLE_TIME_S, Config, Tx40Config
from pipeline.identification.measure import JointRecord, ProcessedData, motor_to_joint, process_record
from pipeline.identification.regressor import (
    BaseParameters,
    RegressorModel,
    base_parameters,
    standard_parameters,
)
from pipeline.robot.model import RobotModel

TX40_DATA_DIR = REPO_ROOT / "data" / "staubli_tx40"
#: the built-in robot of the record (robots/staubli_tx40)
TX40_ROBOT_NAME = "staubli_tx40"
#: joint offsets after the motor -> joint conversion (README of the record)
TX40_JOINT_OFFSETS_RAD = np.array([0.0, -np.pi / 2, np.pi / 2, 0.0, 0.0, 0.0])
#: reference result of the README (OLS, fitted and scored on the same samples)
TX40_REFERENCE = {"n_base_parameters": 58, "condition_number": 970.0, "rms_Nm": 3.35}


@dataclass
class Tx40Result:
    n_base_parameters: int
    condition_number: float
    rms_all_ols_Nm: float
    rms_all_ols_raw_torque_Nm: float
    heldout_rms_Nm: dict[str, float]
    heldout_rms_per_joint_Nm: dict[str, list[float]]
    train_rms_Nm: dict[str, float]
    physically_consistent: bool
    ols_consistent: bool
    physical_parameters: np.ndarray
    ols_beta: np.ndarray
    base: BaseParameters
    heldout_t_s: np.ndarray
    heldout_tau_Nm: np.ndarray
    heldout_pred_Nm: dict[str, np.ndarray]
    details: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {
            "tx40_n_base_parameters": self.n_base_parameters,
            "tx40_condition_number": self.condition_number,
            "tx40_rms_all_ols_Nm": self.rms_all_ols_Nm,
            "tx40_rms_all_ols_raw_torque_Nm": self.rms_all_ols_raw_torque_Nm,
            "tx40_heldout_rms_Nm_ols": self.heldout_rms_Nm["ols"],
            "tx40_heldout_rms_Nm_wls": self.heldout_rms_Nm["wls"],
            "tx40_heldout_rms_Nm_physical": self.heldout_rms_Nm["physical"],
            "tx40_physically_consistent": self.physically_consistent,
            "tx40_reference": dict(TX40_REFERENCE),
        }


TX40_FILES = ("pos_read_data.csv", "curr_data.csv")


def check_tx40_config(cfg: Tx40Config, field: str = "identification.tx40") -> None:
    """Cheap early check (no robot, no parsing of the numbers): the record's folder and its two
    files exist, and the samples left after ``max_samples``, decimation and the border drop are
    enough for the held-out fit of the standard parameters. Raises ConfigError / DataFileError."""
    d = Path(cfg.data_dir) if cfg.data_dir else TX40_DATA_DIR
    if not d.is_dir():
        what = "does not exist" if not d.exists() else "is not a folder"
        raise ConfigError(None, f"{field}.data_dir", f"{str(d)!r} {what} (expected the folder of the TX40 record with "
                          f"{' and '.join(TX40_FILES)}; empty: data/staubli_tx40)")
    n_rows = []
    for name in TX40_FILES:
        path = d / name
        if not path.is_file():
            raise DataFileError(path, None, f"file not found (a TX40 record folder holds {' and '.join(TX40_FILES)}; "
                                f"set by {field}.data_dir)")
        try:
            with path.open("rb") as fh:
                n_rows.append(sum(1 for line in fh if line.strip()) - 1)   # minus the header line
        except OSError as exc:
            raise DataFileError(path, None, f"cannot read: {exc}") from None
    n_raw = min(n_rows)
    if cfg.max_samples > 0:
        n_raw = min(n_raw, cfg.max_samples)
    nq = len(TX40_JOINT_OFFSETS_RAD)
    n_params = 14 * nq                      # 10 inertial + rotor, viscous, Coulomb, offset per joint
    n_proc = -(-n_raw // cfg.decimation) - 2 * cfg.border_samples
    n_train = int(cfg.train_fraction * n_proc)
    if n_train <= n_params or n_proc - n_train < 1:   # the fits need more samples than parameters
        need_train = n_params + 1
        need = (math.ceil(need_train / cfg.train_fraction) + 1 + 2 * cfg.border_samples) * cfg.decimation
        key = f"{field}.max_samples" if cfg.max_samples > 0 else f"{field}.data_dir"
        raise ConfigError(None, key, f"{n_raw} raw samples of the TX40 record leave {max(n_train, 0)} for the fit "
                          f"after decimation by {cfg.decimation}, {cfg.border_samples} dropped at each end and "
                          f"train_fraction {cfg.train_fraction:g}: the fit needs more samples than the {n_params} "
                          f"standard parameters, at least about {need} raw samples")


def load_tx40_record(robot: RobotModel, data_dir: str | Path | None = None, max_samples: int = 0) -> JointRecord:
    """The two CSV files (motor side) -> joint-side :class:`JointRecord`."""
    d = Path(data_dir) if data_dir else TX40_DATA_DIR
    files = {"q": d / TX40_FILES[0], "tau": d / TX40_FILES[1]}
    arrays = {}
    for key, path in files.items():
        if not path.is_file():
            raise DataFileError(path, None, "file not found (the TX40 record is vendored in data/staubli_tx40)")
        try:
            arrays[key] = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2,
                                     max_rows=max_samples if max_samples > 0 else None)
        except ValueError as exc:
            raise DataFileError(path, "values", f"not numeric CSV ({exc})") from None
        if arrays[key].shape[1] != robot.nq:
            raise DataFileError(path, "columns", f"{arrays[key].shape[1]} columns, expected {robot.nq}")
    if arrays["q"].shape[0] != arrays["tau"].shape[0]:
        raise DataFileError(d, "pos_read_data.csv/curr_data.csv",
                            f"mismatched lengths {arrays['q'].shape[0]} and {arrays['tau'].shape[0]}")
    q, tau = motor_to_joint(arrays["q"], arrays["tau"], robot.actuation.gear_matrix)
    q = q + TX40_JOINT_OFFSETS_RAD
    t = np.arange(q.shape[0]) * TX40_SAMPLE_TIME_S
    rec = JointRecord(t, q, tau, str(d))
    rec.validate(robot.nq)
    return rec


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(r) ** 2)))


@dataclass
class HeldOutValidation:
    """Fit on the first ``train_fraction`` of a record, score on the rest (:func:`heldout_validation`)."""

    ols: est_mod.LeastSquaresEstimate
    wls: est_mod.LeastSquaresEstimate
    phys: est_mod.PhysicalEstimate
    n_train: int
    n_samples: int
    t_s: np.ndarray  # times of the held-out samples (processed rate, from the record's start)
    q: np.ndarray  # held-out positions (n_test, nq)
    tau_Nm: np.ndarray  # measured (processed) held-out torques (n_test, nq)
    pred: dict[str, np.ndarray]  # "ols" | "wls" | "physical" -> predicted held-out torques
    rms_Nm: dict[str, float]  # overall RMS error per estimator
    rms_per_joint_Nm: dict[str, list[float]]


def heldout_validation(
    data: ProcessedData, base: BaseParameters, p_nominal: np.ndarray, nq: int, train_fraction: float,
    regularization: float, max_iter: int, field_name: str = "train_fraction", n_rows: int | None = None,
) -> HeldOutValidation:
    """Held-out test of a (non-periodic) record: OLS, Gautier's WLS and the physically consistent
    fit (log-Cholesky, paper ``004_abbe750b8bbcc3aa.txt`` §4.1) on the first ``train_fraction`` of
    the processed samples, torques predicted on the rest (the last samples, never seen by the fit).
    ``n_rows``: measured torques per sample when only some of the ``nq`` joints are (default nq)."""
    nv, nq = nq, (nq if n_rows is None else n_rows)
    n = data.n_samples
    ntr = int(train_fraction * n)
    if not 0 < ntr < n:
        raise DataFileError(None, field_name, f"{train_fraction} of {n} samples leaves no data to fit or to score")
    Wb = base.base_regressor(data.Y)
    y = data.y
    tr, te = slice(0, ntr * nq), slice(ntr * nq, None)
    ols = est_mod.ols(Wb[tr], y[tr], nq)
    wls = est_mod.wls(Wb[tr], y[tr], nq)
    phys = est_mod.physical_fit(data.Y[tr], y[tr], nv, p_nominal, wls.joint_sigma_Nm,
                                regularization=regularization, max_iter=max_iter, n_rows=nq)
    pred = {
        "ols": (Wb[te] @ ols.beta).reshape(-1, nq),
        "wls": (Wb[te] @ wls.beta).reshape(-1, nq),
        "physical": (data.Y[te] @ phys.p).reshape(-1, nq),
    }
    tau_te = y[te].reshape(-1, nq)
    return HeldOutValidation(
        ols=ols, wls=wls, phys=phys, n_train=ntr, n_samples=n,
        t_s=np.arange(ntr, n) * data.sample_time_s, q=data.q[ntr:], tau_Nm=tau_te, pred=pred,
        rms_Nm={k: _rms(tau_te - v) for k, v in pred.items()},
        rms_per_joint_Nm={k: np.sqrt(np.mean((tau_te - v) ** 2, axis=0)).tolist() for k, v in pred.items()},
    )


def run_tx40(robot: RobotModel, config: Tx40Config | None = None, rng: np.random.Generator | None = None) -> Tx40Result:
    """The whole TX40 study (see the module docstring)."""
    with single_thread_blas():
        return _run_tx40_impl(robot=robot, config=config, rng=rng)


def _run_tx40_impl(robot: RobotModel, config: Tx40Config | None = None,
                   rng: np.random.Generator | None = None) -> Tx40Result:
    """The whole TX40 study (see the module docstring)."""
    cfg = config or Tx40Config()
    rng = rng if rng is not None else np.random.default_rng(cfg.base_seed)
    nq = robot.nq
    rec = load_tx40_record(robot, cfg.data_dir or None, cfg.max_samples)
    act = robot.actuation
    reg = RegressorModel(robot.model, act.gear_matrix, act.coulomb_smoothing_rad_s)
    data: ProcessedData = process_record(rec, reg, cfg.cutoff_hz, cfg.decimation, cfg.border_samples)
    base = base_parameters(reg, rng, lower=robot.limits.lower_rad, upper=robot.limits.upper_rad)
    Wb = base.base_regressor(data.Y)
    y = data.y
    n = data.n_samples
    # reference-style figures: OLS fitted and scored on all samples
    ols_all = est_mod.ols(Wb, y, nq)
    cond = float(np.linalg.cond(Wb))
    tau_raw = rec.tau_Nm[:: cfg.decimation][cfg.border_samples : cfg.border_samples + n]
    rms_raw = _rms(tau_raw.ravel() - Wb @ ols_all.beta)
    p_nom = standard_parameters(robot.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    ho = heldout_validation(data, base, p_nom, nq, cfg.train_fraction, cfg.regularization, cfg.max_iter,
                            "identification.tx40.train_fraction")
    ols, wls, phys, ntr = ho.ols, ho.wls, ho.phys, ho.n_train
    # is the OLS fit physically consistent? (its base parameters have no standard realisation
    # check here; the README notes a negative rotor inertia of axis 6, a base parameter on its own)
    names = base.names
    ia6 = [i for i, nm in enumerate(names) if nm.split(" ")[0] == f"j{nq}.Ia"]
    ols_consistent = not (ia6 and ols_all.beta[ia6[0]] <= 0)
    off = 10 * (robot.model.njoints - 1)
    return Tx40Result(
        n_base_parameters=base.n_base,
        condition_number=cond,
        rms_all_ols_Nm=ols_all.rms_Nm,
        rms_all_ols_raw_torque_Nm=rms_raw,
        heldout_rms_Nm=ho.rms_Nm,
        heldout_rms_per_joint_Nm=ho.rms_per_joint_Nm,
        train_rms_Nm={"ols": ols.rms_Nm, "wls": wls.rms_Nm, "physical": phys.rms_Nm},
        physically_consistent=phys.consistent,
        ols_consistent=ols_consistent,
        physical_parameters=phys.p,
        ols_beta=ols.beta,
        base=base,
        heldout_t_s=ho.t_s,
        heldout_tau_Nm=ho.tau_Nm,
        heldout_pred_Nm=ho.pred,
        details={
            "n_samples": n,
            "n_train": ntr,
            "sample_time_s": data.sample_time_s,
            "physical_status": phys.status,
            "physical_iterations": phys.iterations,
            "min_pseudo_inertia_eig": phys.min_pseudo_inertia_eig,
            "rotor_inertia_kgm2": phys.p[off : off + nq].tolist(),
            "viscous_Nms_rad": phys.p[off + nq : off + 2 * nq].tolist(),
            "coulomb_Nm": phys.p[off + 2 * nq : off + 3 * nq].tolist(),
            "offset_Nm": phys.p[off + 3 * nq :].tolist(),
            "ols_ia6_base_value": float(ols_all.beta[ia6[0]]) if ia6 else None,
        },
    )


def tx40_wanted(cfg: Config, robot: RobotModel) -> bool:
    """Fit the Stäubli TX40 record? ``run_tx40`` when set, else only when the robot is the TX40
    or ``tx40.data_dir`` points to a record."""
    if cfg.run_tx40 is not None:
        return bool(cfg.run_tx40)
    return getattr(robot, "name", "") == TX40_ROBOT_NAME or bool(cfg.tx40.data_dir)


def tx40_record(robot: RobotModel, cfg: Config, timings: dict[str, float]) -> Tx40Result | None:
    """The stage's step: the Stäubli TX40 record's fit, when wanted (:func:`tx40_wanted`), timed
    (``timings["tx40_s"]``)."""
    if not tx40_wanted(cfg, robot):
        return None
    t1 = time.perf_counter()
    tx = run_tx40(RobotModel.load(TX40_ROBOT_NAME), cfg.tx40)   # its own fixed seed (tx40.base_seed)
    timings["tx40_s"] = time.perf_counter() - t1
    return tx
