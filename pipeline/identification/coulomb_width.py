"""The Coulomb friction's smoothing width per joint, chosen on a record's training part.

robot.yaml states the width ``w`` of the smoothed sign ``tanh(v / w)``, often one assumed numerical
smoothing (0.01 rad/s) for every joint. On a recorded arm the logged effort changes sign over a
band of velocities that the drive sets: presliding displacement of the gear (Armstrong-Hélouvry,
Dupont & Canudas de Wit 1994, Automatica 30(7)), the current loop and the driver's filtering of the
current it logs. A model whose Coulomb term switches at 0.01 rad/s where the effort takes 0.1 rad/s
leaves a step of twice the Coulomb level in the residual at every reversal. The sigmoid friction of
Gaz et al. 2019 (RA-L 4(4), eq. 6) has this width as a fitted parameter (``2 / phi2``).

The width is a shape parameter of the friction law, one per joint: chosen on the grid
:data:`COULOMB_WIDTHS_RAD_S` by coordinate descent (at most :data:`MAX_SWEEPS` sweeps over the
joints), each joint's the one whose Gautier WLS fit of the base parameters on the first
``train_fraction`` of the samples leaves the smallest weighted residual sum of squares
``sum_i ||r_i||^2 / sigma_i^2`` over all rows (``sigma_i``: the rows' residual RMS at the stated
widths, held fixed so the scores compare; every row, so coupled axes count; a row without an
equation, a joint at rest of :mod:`.dwell`, counts in neither). The weighted residual of each trial is
that of the torques and the columns the joint's width reaches after projecting out the others
(Frisch-Waugh-Lovell: one QR per joint and sweep). The held-out tail never enters. A joint keeps the
stated width unless another lowers that sum by at least the share of one row's residual RMS falling
by :data:`MIN_RELATIVE_GAIN`, ``2 g / n_rows`` of it, and a forward check inside the training part
confirms it by the same margin: fitted on its first :data:`FORWARD_FIT_FRACTION`, the model with the
chosen width predicts the rest of it better than with the stated one (else that joint keeps the stated
width). A width is a prior stated in robot.yaml; only clear evidence moves it. On the Stäubli TX40's
motor-torque record, widths that lowered the training residual by 4-8 % predicted its held-out tail
worse; on the UR10's current log the gains are 18-67 % and hold on its tail. The chosen widths are the
friction law of the identified robot handed on (``actuation.coulomb_smoothing_rad_s`` per joint), so the
control and trajectory stages switch each joint's Coulomb friction as the fits did.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from pipeline.identification.estimate import weighted_solution
from pipeline.identification.friction import load_columns, load_free_torque
from pipeline.identification.measure import ProcessedData
from pipeline.identification.regressor import RegressorModel

#: the Coulomb smoothing widths a joint may take (rad/s, about 1.5x apart over the range drives show)
COULOMB_WIDTHS_RAD_S = (0.002, 0.003, 0.005, 0.007, 0.01, 0.015, 0.02, 0.03, 0.05, 0.07, 0.1, 0.15, 0.2, 0.3, 0.5)
#: a width other than the stated one must lower a row's residual RMS by at least this fraction, on the
#: training part and in the forward check inside it
MIN_RELATIVE_GAIN = 0.1
MAX_SWEEPS = 3
#: the forward check fits on this first fraction of the training part and predicts the rest of it
FORWARD_FIT_FRACTION = 0.7


@dataclass
class CoulombWidths:
    """The widths chosen on a record (:func:`choose_widths`) and the training residuals behind them."""

    stated_rad_s: np.ndarray         # (nv,) robot.yaml's
    chosen_rad_s: np.ndarray         # (nv,)
    train_rms_stated_Nm: np.ndarray  # (n_rows,) WLS residual RMS on the training part, stated widths
    train_rms_chosen_Nm: np.ndarray  # (n_rows,) the same with the chosen widths
    n_train: int

    @property
    def changed(self) -> np.ndarray:
        """Joint indices whose width differs from the stated one."""
        return np.flatnonzero(~np.isclose(self.chosen_rad_s, self.stated_rad_s))

    def summary(self, per_joint: Callable[[np.ndarray], list]) -> dict:
        """Summary entries (JSON-able; ``per_joint`` maps a value per torque row to all joints)."""
        return {"coulomb_width_rad_s": [float(w) for w in self.chosen_rad_s],
                "coulomb_width_stated_rad_s": [float(w) for w in self.stated_rad_s],
                "coulomb_width_train_rms_stated_Nm": per_joint(self.train_rms_stated_Nm),
                "coulomb_width_train_rms_chosen_Nm": per_joint(self.train_rms_chosen_Nm),
                "coulomb_width_selection": f"grid {list(COULOMB_WIDTHS_RAD_S)} rad/s, WLS on the first "
                                           f"{self.n_train} samples, a forward check inside them "
                                           "(the held-out tail not used)"}

    def note(self) -> str | None:
        """The warning that the widths differ from robot.yaml's (None: all as stated)."""
        if not self.changed.size:
            return None
        which = ", ".join(f"joint {j + 1} {self.chosen_rad_s[j]:g} rad/s" for j in self.changed)
        return (f"the record's efforts change sign over wider velocity bands than robot.yaml's Coulomb smoothing "
                f"({', '.join(f'{w:g}' for w in np.unique(self.stated_rad_s))} rad/s): this stage's fits and "
                f"validation use {which}, and the robot handed on carries them")


def coulomb_rows(data: ProcessedData, reg: RegressorModel, widths_rad_s: np.ndarray) -> np.ndarray:
    """(N, n_rows, nv) the Coulomb columns of ``data``'s samples at the per-joint ``widths_rad_s``: block
    means of :meth:`RegressorModel.coulomb_block` over each sample's full-rate velocities."""
    v_all = data.v[:, None, :] if data.v_full is None else data.v_full
    block = np.mean([reg.coulomb_block(v_all[:, k, :], widths_rad_s) for k in range(v_all.shape[1])], axis=0)
    return block if data.rows is None else block[:, data.rows]


def with_widths(data: ProcessedData, reg: RegressorModel, widths_rad_s: np.ndarray) -> ProcessedData:
    """``data`` with its regressor's Coulomb columns at ``widths_rad_s`` (nv,)."""
    n, nr = data.tau.shape
    Y = data.Y.reshape(n, nr, -1).copy()
    Y[:, :, reg.coulomb_columns] = coulomb_rows(data, reg, widths_rad_s)
    return replace(data, Y=Y.reshape(n * nr, -1))


def _row_rms(residual: np.ndarray, has_equation: np.ndarray) -> np.ndarray:
    """(n_rows,) the RMS of each torque row's ``residual`` (n, n_rows) over the samples where it has an equation."""
    return np.sqrt(np.sum(residual**2, axis=0) / np.maximum(np.sum(has_equation, axis=0), 1))


def _fit_residual(Wb: np.ndarray, y: np.ndarray, joint_sigma: np.ndarray) -> np.ndarray:
    """(n, n_rows) the residual of :func:`.estimate.weighted_solution`."""
    return (y - Wb @ weighted_solution(Wb, y, joint_sigma)).reshape(-1, len(joint_sigma))


def choose_widths(data: ProcessedData, reg: RegressorModel, base_regressor: Callable[[np.ndarray], np.ndarray],
                  n_train: int, offsets: np.ndarray | None = None) -> CoulombWidths:
    """Per-joint Coulomb smoothing widths on the first ``n_train`` samples of ``data`` (module doc).
    ``offsets``: mask of the base parameters that are torque offsets; given, each row's scoring fit also
    has the load-dependent Coulomb column ``|tau_load| tanh(v / w)`` of :mod:`.friction` (load torque
    from the fit at the stated widths, :func:`.friction.load_free_torque`), whose width is the joint's."""
    nr = data.tau.shape[1]
    nv = reg.nv
    stated = reg.joint_coulomb_width_rad_s
    train = replace(data, q=data.q[:n_train], v=data.v[:n_train], a=data.a[:n_train], tau=data.tau[:n_train],
                    Y=data.Y[: n_train * nr],
                    v_full=None if data.v_full is None else data.v_full[:n_train])
    y = train.y
    n_std = train.Y.shape[1]
    unit_rows = np.eye(n_std)[np.arange(n_std)[reg.coulomb_columns]]
    base_of_column = base_regressor(unit_rows)              # (nv, nb): a standard Coulomb column in the base set
    grid = np.unique(np.concatenate([COULOMB_WIDTHS_RAD_S, stated]))
    # the Coulomb columns of every joint at every width of the grid: (n_grid, n_train, nr, nv)
    candidates = np.stack([coulomb_rows(train, reg, np.full(nv, g)) for g in grid])
    stated_idx = np.array([int(np.argmin(np.abs(grid - s))) for s in stated])
    current = stated_idx.copy()
    Wb = base_regressor(train.Y)                            # the stated widths: the record's regressor
    nb = Wb.shape[1]
    row_of_joint: dict[int, int] = {}
    has_equation = np.any(train.Y.reshape(n_train, nr, -1) != 0, axis=2)     # (n_train, nr): :mod:`.dwell`
    sigma = np.maximum(_row_rms(_fit_residual(Wb, y, np.ones(nr)), has_equation), 1e-12)
    rows = np.arange(nv) if data.rows is None else np.asarray(data.rows)
    v_rows = (train.v[:, None, :] if train.v_full is None else train.v_full)[..., rows]
    load_block = np.zeros((n_train * nr, 0))
    if offsets is not None:     # the load columns of every row at every width: (n_grid, n_train * nr, nr)
        beta0 = weighted_solution(Wb, y, sigma)
        load_Nm = load_free_torque(Wb, beta0, offsets, nr, None, v_rows)
        load_grid = np.stack([load_columns(load_Nm, v_rows, g, np.arange(nr)) for g in grid])
        row_of_joint = {int(j): i for i, j in enumerate(rows)}
        load_block = load_grid[current[rows], :, np.arange(nr)].T.copy()
        Wb = np.hstack([Wb, load_block])

    w_rows = np.tile(1.0 / sigma, n_train)
    yw = y * w_rows

    def reached(j: int) -> tuple[np.ndarray, np.ndarray]:
        """The columns of ``Wb`` a width of joint ``j`` reaches (its Coulomb column's base columns, then its
        row's load column) and the base columns alone."""
        in_base = np.flatnonzero(base_of_column[j] != 0)
        return np.concatenate([in_base, [nb + row_of_joint[j]] if j in row_of_joint else []]).astype(int), in_base

    def columns_at(j: int, g: int) -> np.ndarray:
        """Those columns with joint ``j``'s width at grid index ``g`` (now at ``current[j]``)."""
        cols_j, in_base = reached(j)
        cols = Wb[:, cols_j].copy()
        delta = candidates[g, :, :, j].ravel() - candidates[current[j], :, :, j].ravel()
        cols[:, : len(in_base)] += np.outer(delta, base_of_column[j][in_base])
        if j in row_of_joint:
            cols[:, -1] = load_grid[g, :, row_of_joint[j]]
        return cols

    best = float(np.sum((_fit_residual(Wb, y, sigma) / sigma) ** 2))
    min_drop = 2 * MIN_RELATIVE_GAIN / nr
    for _ in range(MAX_SWEEPS):
        moved = False
        for j in range(nv):
            cols_j = reached(j)[0]
            # Frisch-Waugh-Lovell: the fit's weighted residual is that of y and the reached columns after
            # projecting out the others (one QR per joint, not one least-squares fit per width)
            Q = np.linalg.qr(Wb[:, np.setdiff1d(np.arange(Wb.shape[1]), cols_j)] * w_rows[:, None])[0]
            y_perp = yw - Q @ (Q.T @ yw)
            trials = []
            for g in (g for g in range(len(grid)) if g != current[j]):
                C = columns_at(j, g) * w_rows[:, None]
                C_perp = C - Q @ (Q.T @ C)
                coef = np.linalg.lstsq(C_perp, y_perp, rcond=None)[0]
                trials.append((float(np.sum((y_perp - C_perp @ coef) ** 2)), g))
            s_new, g_new = min(trials)
            if s_new < best * (1 - min_drop):
                Wb[:, cols_j] = columns_at(j, g_new)
                best, current[j], moved = s_new, g_new, True
        if not moved:
            break
    # the forward check inside the training part: a joint keeps its chosen width only when the fit on the first
    # FORWARD_FIT_FRACTION of the training samples predicts the rest of them better with it than with the stated
    # width, by the same margin
    m = int(FORWARD_FIT_FRACTION * n_train)

    def forward(W: np.ndarray) -> float:
        beta = weighted_solution(W[: m * nr], y[: m * nr], sigma)
        return float(np.sum(((y[m * nr:] - W[m * nr:] @ beta) * w_rows[m * nr:]) ** 2))

    for j in map(int, np.flatnonzero(current != stated_idx)):
        W = Wb.copy()
        W[:, reached(j)[0]] = columns_at(j, int(stated_idx[j]))
        if not forward(Wb) < forward(W) * (1 - min_drop):
            Wb, current[j] = W, stated_idx[j]
    chosen = grid[current]
    r_chosen = _fit_residual(Wb, y, sigma)
    r_stated = _fit_residual(np.hstack([base_regressor(train.Y), load_block]), y, sigma)
    return CoulombWidths(stated, chosen, _row_rms(r_stated, has_equation), _row_rms(r_chosen, has_equation), n_train)
