"""Periodic Fourier excitation trajectories, their limits and feasibility check (paper
``004_abbe750b8bbcc3aa.txt`` §4.2.1, after Swevers et al. [14]).

Each joint follows a finite Fourier series with base pulsation ``w_f = 2 pi f_f`` and ``L``
harmonics (§4.2.1):

    q_i(t) = q_i0 + sum_l a_il / (w_f l) sin(w_f l t) - b_il / (w_f l) cos(w_f l t)
    v_i(t) = sum_l a_il cos(w_f l t) + b_il sin(w_f l t)
    a_i(t) = sum_l -a_il w_f l sin(w_f l t) + b_il w_f l cos(w_f l t)

Rest to rest (and periodic): ``v_i(0) = sum_l a_il = 0`` and ``a_i(0) = w_f sum_l l b_il = 0``,
two linear equalities per joint.

``check_trajectory`` verifies a trajectory on a fine grid against joint position, velocity,
acceleration and nominal torque limits and the capsule self/floor clearances;
``random_feasible_trajectories`` draws the random baseline (and the optimiser's starts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.core.errors import InfeasibleError
from pipeline.identification.tcp_motion import tcp_speed_acceleration
from pipeline.robot.model import RobotModel


# ------------------------------------------------------------------------------ trajectories
@dataclass
class FourierTrajectory:
    """Periodic Fourier trajectory; ``coefficients`` (nq, 2L+1) = ``[q0, a_1..a_L, b_1..b_L]``."""

    coefficients: np.ndarray
    base_frequency_hz: float

    @property
    def harmonics(self) -> int:
        return (self.coefficients.shape[1] - 1) // 2

    @property
    def period_s(self) -> float:
        return 1.0 / self.base_frequency_hz

    @property
    def nq(self) -> int:
        return self.coefficients.shape[0]

    def basis(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return fourier_basis(np.asarray(t_s, float), self.base_frequency_hz, self.harmonics)

    def evaluate(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, v, a), each (N, nq)."""
        bq, bv, ba = self.basis(t_s)
        c = self.coefficients
        return bq @ c.T, bv @ c.T, ba @ c.T

    def sample_times(self, n: int, periods: int = 1) -> np.ndarray:
        return np.arange(n * periods) * (self.period_s / n)

    def to_dict(self) -> dict:
        return {
            "base_frequency_hz": self.base_frequency_hz,
            "harmonics": self.harmonics,
            "coefficients": self.coefficients.tolist(),
        }


def fourier_basis(
    t_s: np.ndarray, base_frequency_hz: float, harmonics: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Basis rows for ``[q0, a_1..a_L, b_1..b_L]``: q = Bq c, v = Bv c, a = Ba c."""
    w = 2 * np.pi * base_frequency_hz
    n = len(t_s)
    ell = np.arange(1, harmonics + 1)
    wl = w * ell
    arg = np.outer(t_s, wl)
    s, c = np.sin(arg), np.cos(arg)
    bq = np.hstack([np.ones((n, 1)), s / wl, -c / wl])
    bv = np.hstack([np.zeros((n, 1)), c, s])
    ba = np.hstack([np.zeros((n, 1)), -s * wl, c * wl])
    return bq, bv, ba


def rest_constraint_matrix(harmonics: int) -> np.ndarray:
    """(2, 2L+1) matrix C with ``C c_i = 0`` <=> joint i starts/ends at rest."""
    ell = np.arange(1, harmonics + 1, dtype=float)
    C = np.zeros((2, 2 * harmonics + 1))
    C[0, 1 : harmonics + 1] = 1.0
    C[1, harmonics + 1 :] = ell / ell.sum()
    return C


# ------------------------------------------------------------------------------ limits
#: a capsule pair whose median clearance over the workspace is below the required margin is close by
#: construction (a compact wrist, the upper arm over the base): it is held at this share of its median
CLOSE_PAIR_SHARE = 0.5
#: random centres drawn for one random trajectory before giving up (random_trajectory)
CENTRE_DRAWS = 200


def pair_clearances_m(robot: RobotModel, self_clearance_m: float) -> np.ndarray:
    """Required clearance per checked capsule pair: ``self_clearance_m``, or for a pair whose median
    clearance over random configurations (:meth:`RobotModel.typical_pair_clearances_m`) is below it,
    :data:`CLOSE_PAIR_SHARE` of that median. Fitted capsules of a compact arm (the Unitree Z1's wrist
    capsules are 15 mm apart in most poses) would otherwise rule out nearly every excitation; the
    margin guards against collisions, not against the links' own geometry."""
    typical = np.asarray(robot.typical_pair_clearances_m(), float)
    close = typical < self_clearance_m
    return np.where(close, CLOSE_PAIR_SHARE * np.maximum(typical, 0.0), float(self_clearance_m))


@dataclass
class ExcitationLimits:
    """Limits the excitation must respect (already multiplied by the margins)."""

    lower_rad: np.ndarray
    upper_rad: np.ndarray
    velocity_rad_s: np.ndarray
    acceleration_rad_s2: np.ndarray
    effort_Nm: np.ndarray
    floor_clearance_m: float
    #: per checked capsule pair (robot.self_collision_pairs) or one value for all
    self_clearance_m: float | np.ndarray
    #: TCP speed and acceleration bounds (inf: none; paper 004 §4.3: 5 m/s and 12 m/s^2)
    tcp_speed_m_s: float = np.inf
    tcp_acceleration_m_s2: float = np.inf

    def tightened(self, factor: float, clearance_m: float) -> ExcitationLimits:
        """Limits scaled by ``factor`` about their middle and clearances ``+ clearance_m`` (the NLP
        works inside the checked limits, so an iterate that stops slightly infeasible or peaks
        between the NLP samples still passes the fine-grid check)."""
        mid = 0.5 * (self.lower_rad + self.upper_rad)
        half = 0.5 * (self.upper_rad - self.lower_rad) * factor
        return ExcitationLimits(mid - half, mid + half, self.velocity_rad_s * factor,
                                self.acceleration_rad_s2 * factor, self.effort_Nm * factor,
                                self.floor_clearance_m + clearance_m, self.self_clearance_m + clearance_m,
                                self.tcp_speed_m_s * factor, self.tcp_acceleration_m_s2 * factor)

    @classmethod
    def from_robot(
        cls,
        robot: RobotModel,
        position_margin: float,
        velocity_margin: float,
        acceleration_margin: float,
        torque_margin: float,
        floor_clearance_m: float,
        self_clearance_m: float,
        tcp_speed_m_s: float | None = None,
        tcp_acceleration_m_s2: float | None = None,
    ) -> ExcitationLimits:
        lim = robot.limits
        mid = 0.5 * (lim.lower_rad + lim.upper_rad)
        half = 0.5 * (lim.upper_rad - lim.lower_rad) * position_margin
        return cls(
            mid - half,
            mid + half,
            lim.velocity_rad_s * velocity_margin,
            lim.acceleration_rad_s2 * acceleration_margin,
            lim.effort_Nm * torque_margin,
            floor_clearance_m,
            pair_clearances_m(robot, self_clearance_m),
            np.inf if tcp_speed_m_s is None else float(tcp_speed_m_s),
            np.inf if tcp_acceleration_m_s2 is None else float(tcp_acceleration_m_s2),
        )

    @property
    def bounds_tcp(self) -> bool:
        return bool(np.isfinite(self.tcp_speed_m_s) or np.isfinite(self.tcp_acceleration_m_s2))


@dataclass
class FeasibilityReport:
    """Worst ratios to the limits on a fine grid (<= 1 feasible) and the capsule clearances."""

    position_ratio: float
    velocity_ratio: float
    acceleration_ratio: float
    torque_ratio: float
    self_clearance_m: float
    floor_clearance_m: float
    tcp_floor_m: float
    feasible: bool
    tcp_speed_max_m_s: float = float("nan")          # largest TCP speed on the grid
    tcp_acceleration_max_m_s2: float = float("nan")  # largest TCP acceleration on the grid

    def to_dict(self) -> dict:
        return {k: (bool(v) if k == "feasible" else float(v)) for k, v in vars(self).items()}

    def tcp_ratio(self, limits: ExcitationLimits) -> float:
        """Largest TCP speed or acceleration over its bound (0 when unbounded)."""
        return max(self.tcp_speed_max_m_s / limits.tcp_speed_m_s,
                   self.tcp_acceleration_max_m_s2 / limits.tcp_acceleration_m_s2)


def nominal_torques(robot: RobotModel, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``robot.inverse_dynamics`` of every row of ``q, v, a`` (N, nq), number for number: ``pin.rnea``
    row by row, the friction terms (elementwise) on all rows at once."""
    model, data = robot.model, robot.model.createData()
    tau = np.array([pin.rnea(model, data, qk, vk, ak) for qk, vk, ak in zip(q, v, a, strict=True)])
    tau0 = tau.reshape(len(q), robot.nq) + robot.friction_torque(v)
    if robot.spec.actuation.coulomb_load_coefficient is None:
        return tau0
    return tau0 + robot.load_friction_torque(tau0, v)


def check_trajectory(
    robot: RobotModel,
    traj: FourierTrajectory,
    limits: ExcitationLimits,
    n_samples: int = 400,
    floor_z_m: float | None = None,
) -> FeasibilityReport:
    """Evaluate every constraint on ``n_samples`` points of one period (nominal dynamics); the
    TCP speed and acceleration are reported always and bounded when ``limits`` bound them."""
    t = traj.sample_times(n_samples)
    q, v, a = traj.evaluate(t)
    mid = 0.5 * (limits.lower_rad + limits.upper_rad)
    half = 0.5 * (limits.upper_rad - limits.lower_rad)
    pos = float(np.max(np.abs(q - mid) / half))
    vel = float(np.max(np.abs(v) / limits.velocity_rad_s))
    acc = float(np.max(np.abs(a) / limits.acceleration_rad_s2))
    trq = float(np.max(np.abs(nominal_torques(robot, q, v, a)) / limits.effort_Nm))
    seg = robot.capsule_segments(q)
    pair, floor = robot.capsule_clearances(seg)
    self_min = float(pair.min()) if pair.size else np.inf
    floor_min = float(floor.min()) if floor.size else np.inf
    fz = robot.spec.collision.floor_z_m if floor_z_m is None else floor_z_m
    tcp = float(robot.positions(q, robot.frame_tcp)[:, 2].min() - fz)
    tcp_v, tcp_a = tcp_speed_acceleration(robot, q, v, a)
    tcp_ratio = max(float(tcp_v.max()) / limits.tcp_speed_m_s, float(tcp_a.max()) / limits.tcp_acceleration_m_s2)
    ok = (
        max(pos, vel, acc, trq, tcp_ratio) <= 1.0 + 1e-9
        and bool(np.all(pair >= limits.self_clearance_m))
        and floor_min >= limits.floor_clearance_m
        and tcp >= limits.floor_clearance_m
    )
    return FeasibilityReport(pos, vel, acc, trq, self_min, floor_min, tcp, bool(ok), float(tcp_v.max()),
                             float(tcp_a.max()))


def random_trajectory(
    robot: RobotModel,
    limits: ExcitationLimits,
    harmonics: int,
    base_frequency_hz: float,
    rng: np.random.Generator,
    n_check: int = 200,
) -> FourierTrajectory:
    """Random Fourier coefficients scaled into the kinematic and torque limits.

    Coefficients ~ N(0, 1/l), projected onto the rest-to-rest constraints, each joint scaled by a
    random fraction (0.3..1) of the largest factor its position/velocity/acceleration limits allow
    and centred at a random point of its range (up to ``CENTRE_DRAWS`` draws until gravity alone stays
    below 90 % of the torque limits there: an arm that its own weight loads near its limits around
    mid-range, e.g. a humanoid's arm held out sideways, needs many); then scaled down until the nominal torques fit
    (and, when ``limits`` bound them, the TCP speed and acceleration). Collisions are not checked
    here (see :func:`random_feasible_trajectories`).
    """
    nq = robot.nq
    L = harmonics
    C = rest_constraint_matrix(L)
    P = np.eye(2 * L + 1) - np.linalg.pinv(C) @ C
    ell = np.arange(1, L + 1)
    traj_t = np.arange(n_check) / (n_check * base_frequency_hz)
    bq, bv, ba = fourier_basis(traj_t, base_frequency_hz, L)
    def torque_ratio(coef: np.ndarray) -> float:
        q, v, a = (b @ coef.T for b in (bq, bv, ba))
        return float(np.max(np.abs(nominal_torques(robot, q, v, a)) / limits.effort_Nm))

    for _ in range(CENTRE_DRAWS):
        coef = np.zeros((nq, 2 * L + 1))
        for i in range(nq):
            c = np.concatenate([[0.0], rng.normal(size=L) / ell, rng.normal(size=L) / ell])
            c = P @ c
            c[0] = 0.0
            qo, vo, ao = bq @ c, bv @ c, ba @ c
            span = qo.max() - qo.min()
            s = min(
                (limits.upper_rad[i] - limits.lower_rad[i]) / max(span, 1e-12),
                limits.velocity_rad_s[i] / max(np.abs(vo).max(), 1e-12),
                limits.acceleration_rad_s2[i] / max(np.abs(ao).max(), 1e-12),
            ) * rng.uniform(0.3, 1.0)
            c = c * s
            lo = limits.lower_rad[i] - (bq @ c).min()
            hi = limits.upper_rad[i] - (bq @ c).max()
            c[0] = rng.uniform(lo, hi) if hi > lo else 0.5 * (lo + hi)
            coef[i] = c
        # torque: largest oscillation scale (bisection) about the mean position that fits
        still = coef.copy()
        still[:, 1:] = 0.0
        if torque_ratio(still) > 0.9:
            continue  # gravity alone is too close to the limit here: draw another centre
        if torque_ratio(coef) > 1.0:
            lo_s, hi_s = 0.0, 1.0
            for _ in range(12):
                mid = 0.5 * (lo_s + hi_s)
                trial = coef.copy()
                trial[:, 1:] *= mid
                lo_s, hi_s = (mid, hi_s) if torque_ratio(trial) <= 1.0 else (lo_s, mid)
            coef[:, 1:] *= 0.97 * lo_s
        if limits.bounds_tcp:  # TCP speed/acceleration: shrink the oscillation about the mean
            for _ in range(10):
                q, v, a = (b @ coef.T for b in (bq, bv, ba))
                tv, ta = tcp_speed_acceleration(robot, q, v, a)
                r = max(tv.max() / limits.tcp_speed_m_s, ta.max() / limits.tcp_acceleration_m_s2)
                if r <= 1.0:
                    break
                coef[:, 1:] *= 0.97 / r
        return FourierTrajectory(coef, base_frequency_hz)
    raise InfeasibleError(
        None, "identification.excitation", "no centre position with static torques below 90 % "
        f"of the (margin-scaled) limits found in {CENTRE_DRAWS} random draws"
    )


#: the NLP keeps inside the checked limits by this factor and extra clearance
NLP_LIMIT_FACTOR = 0.98
NLP_EXTRA_CLEARANCE_M = 0.005

#: oscillation scales tried, in turn, on a random draw that violates a limit or collides
SHRINK_FACTORS = (1.0, 0.7, 0.5, 0.35)


def random_feasible_trajectories(
    robot: RobotModel,
    limits: ExcitationLimits,
    harmonics: int,
    base_frequency_hz: float,
    count: int,
    rng: np.random.Generator,
    max_tries: int | None = None,
    n_check: int = 200,
) -> list[FourierTrajectory]:
    """``count`` random trajectories that pass :func:`check_trajectory` (collisions included).

    Plain rejection sampling for the first ``5 count`` draws; after that (compact arms whose
    capsules collide for most random swings) a draw whose centre pose collides is skipped and
    otherwise its oscillation is scaled by :data:`SHRINK_FACTORS` in turn, the first feasible
    scale being kept."""
    out: list[FourierTrajectory] = []
    tries = 0
    max_tries = max_tries if max_tries is not None else 50 * count
    plain_tries = 5 * count
    while len(out) < count and tries < max_tries:
        tries += 1
        traj = random_trajectory(robot, limits, harmonics, base_frequency_hz, rng, n_check)
        # plain rejection sampling first; a compact arm (capsules close together) collides for
        # most random swings, then shrink the oscillation about a collision-free centre
        factors = SHRINK_FACTORS[:1] if tries <= plain_tries else SHRINK_FACTORS
        if tries > plain_tries:
            centre = FourierTrajectory(traj.coefficients * np.r_[1.0, np.zeros(2 * harmonics)], base_frequency_hz)
            if not check_trajectory(robot, centre, limits, 2).feasible:
                continue
        for shrink in factors:
            coef = traj.coefficients.copy()
            coef[:, 1:] *= shrink
            trial = FourierTrajectory(coef, base_frequency_hz)
            if check_trajectory(robot, trial, limits, n_check).feasible:
                out.append(trial)
                break
    if len(out) < count:
        raise InfeasibleError(
            None,
            "identification.excitation",
            f"only {len(out)} of {count} random Fourier trajectories are feasible after "
            f"{tries} tries (limits, torques or capsule collisions)",
        )
    return out


# ------------------------------------------------------------------------------ criterion
