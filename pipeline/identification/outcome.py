"""What the identification stage's steps hand to each other and to the report, and the model it hands
on: the identified robot (standard parameters, rotor inertia, friction) and its friction.

Steps (:mod:`pipeline.identification.stage`): the regressor and its base set (:class:`Regressors`),
the data (:class:`Measured`), the fits on all samples (:class:`Fits`), the scores on the
validation torques (:class:`Validation`), all of them for the report (:class:`Outcome`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.identification.coulomb_width import CoulombWidths
from pipeline.identification.design import ExcitationResult
from pipeline.identification.dwell import Dwells
from pipeline.identification.effort_unit import EffortUnit
from pipeline.identification.estimate import HacCovariance, LeastSquaresEstimate, PhysicalEstimate
from pipeline.identification.fourier import ExcitationLimits, FourierTrajectory
from pipeline.identification.friction import LoadFit, LoadFriction, StribeckFit
from pipeline.identification.joints import JointSelection
from pipeline.identification.measure import JointRecord, ProcessedData, StictionExclusion
from pipeline.identification.regressor import BaseParameters, RegressorModel
from pipeline.identification.tx40 import HeldOutValidation, Tx40Result
from pipeline.robot.handoff import JointFriction
from pipeline.robot.iso9283 import IsoPathConfig
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import DynamicLayout, set_dynamic_parameters
from pipeline.robot.vendor_urdf import consistent_inertia


@dataclass
class Regressors:
    """The regressor of the current model, its base set and the nominal model's structural one, the
    gear coupling of the torques, the user's record (None: simulated) and the joints the fit uses."""

    coupled: bool
    record: JointRecord | None
    selection: JointSelection
    reg: RegressorModel
    base_design: BaseParameters      # structural base set, decided on the nominal model
    base: BaseParameters             # the same set with the current model's combinations
    #: base parameters the excitation could not bring under the condition-number bound, left out of
    #: the design and the fits (:func:`pipeline.identification.experiment.excite_and_measure`), and
    #: the condition number of the full set's best excitation
    dropped: list[str] = field(default_factory=list)
    dropped_cond: float | None = None

    @property
    def used(self) -> np.ndarray:
        """0-based joints whose torques the fit uses."""
        return self.selection.used

    @property
    def n_used(self) -> int:
        """How many joints the fit uses."""
        return len(self.selection.used)


@dataclass
class Measured:
    """Processed data (period-averaged, filtered, decimated) and, when simulated, the excitation."""

    data: ProcessedData
    source: str
    excitation: ExcitationResult | None = None
    limits: ExcitationLimits | None = None
    trajectory: FourierTrajectory | None = None
    #: an arm whose dry friction sticks: the samples in the stiction band left out of the fits (None: none)
    stiction: StictionExclusion | None = None
    #: a user's record: what its efforts were read as and the scale applied (None: simulated)
    effort_unit: EffortUnit | None = None
    #: a user's record: the Coulomb smoothing widths chosen on its training part (None: robot.yaml's)
    coulomb_widths: CoulombWidths | None = None
    #: a user's record: the rows at which a joint dwells, left out of the fits (None: none left out)
    dwells: Dwells | None = None

    @property
    def fit_data(self) -> ProcessedData:
        """The samples the fits on all samples use: a record's dwell rows without an equation (:mod:`.dwell`)."""
        return self.data if self.dwells is None else self.dwells.without_equations(self.data)

    def validation_data(self, train_fraction: float) -> ProcessedData:
        """The samples of a held-out validation: the dwell rows of the training part (the first
        ``train_fraction``) without an equation, every sample of the held-out tail as measured."""
        if self.dwells is None:
            return self.data
        return self.dwells.without_equations(self.data, int(train_fraction * self.data.n_samples))


@dataclass
class LoadCandidate:
    """The friction model with load-dependent Coulomb friction (:func:`.friction.fit_load_friction`):
    its fit, the torques without its friction terms, the WLS and the physically consistent fits on them."""

    fit: LoadFit
    y_fit: np.ndarray
    wls: LeastSquaresEstimate
    phys: PhysicalEstimate


@dataclass
class Fits:
    """Fits on all samples: base regressor and torques, condition numbers, OLS / WLS, the optional
    Stribeck term (``stribeck``) and the physically consistent fits with (``phys``) and without it
    (``phys_vc``, viscous + Coulomb)."""

    Wb: np.ndarray
    y: np.ndarray
    cond_data: float
    cond_data_structural: float
    wls_vc: LeastSquaresEstimate
    max_excess_Nm: np.ndarray
    stribeck: StribeckFit | None
    y_fit: np.ndarray
    ols: LeastSquaresEstimate
    wls: LeastSquaresEstimate
    p_nom: np.ndarray
    phys: PhysicalEstimate
    phys_vc: PhysicalEstimate
    #: the candidate with load-dependent Coulomb friction (None: not fitted, coupled axes)
    load_candidate: LoadCandidate | None = None
    #: a record fitted with the Stribeck term: the load-dependent candidate nested in the viscous + Coulomb
    #: fit as well (None: not fitted)
    load_candidate_vc: LoadCandidate | None = None
    #: its fit when it is the handed-on model, else None
    load: LoadFit | None = None
    #: why the candidate was not fitted or not scored ("": it was)
    load_note: str = ""
    #: 0-based joints on which the robot handed on keeps robot.yaml's rotor inertia
    #: (:func:`pipeline.identification.handed_on.unseen_rotor_inertia_joints`)
    stated_rotor_joints: np.ndarray = field(default_factory=lambda: np.zeros(0, int))


@dataclass
class ValidationTrajectory:
    """Joint states (N, nq) sampled at ``t_s`` that validate the fits, what they are (``label``:
    ``iso9283``, ``fourier`` or a record's held-out tail) and why (``note``)."""

    t_s: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    label: str
    note: str = ""


@dataclass
class Validation:
    """Measured and predicted torques on the validation trajectory and their RMS per joint, the
    torque noise sigma and where it comes from, the ISO 9283 path settings the validation used or
    fell back from (None: a record's held-out tail)."""

    trajectory: ValidationTrajectory
    tau_Nm: np.ndarray
    pred_phys: np.ndarray
    pred_wls: np.ndarray
    pred_vc: np.ndarray
    rms_phys: np.ndarray
    rel_phys: np.ndarray
    rms_wls: np.ndarray
    rel_wls: np.ndarray
    noise_sigma: np.ndarray | None
    noise_source: str
    iso: IsoPathConfig | None = None
    heldout: HeldOutValidation | None = None    # a record's held-out tail
    #: predictions of the load-dependent candidate (physical, WLS), None when it was not fitted
    pred_load: np.ndarray | None = None
    pred_load_wls: np.ndarray | None = None
    #: the same of the candidate nested in the viscous + Coulomb fit (:attr:`Fits.load_candidate_vc`)
    pred_load_vc: np.ndarray | None = None
    pred_load_vc_wls: np.ndarray | None = None
    #: (N, n_used) bool: the samples the RMS counts, outside the stiction band ``|v| >= min_speed_rad_s``
    #: of an arm whose dry friction sticks (None: every sample; :mod:`pipeline.identification.validate`)
    scored: np.ndarray | None = None
    min_speed_rad_s: float = 0.0

    @property
    def rms_over_noise(self) -> np.ndarray:
        """Validation RMS over the noise sigma per joint (NaN without a sigma)."""
        if self.noise_sigma is None:
            return np.full(len(self.rms_phys), np.nan)
        return self.rms_phys / self.noise_sigma


@dataclass
class Outcome:
    """Everything the report draws on: the steps' results, the friction part of the summary, the
    base-parameter covariance (and the white-residual sigmas it replaced), the truth scores (only
    when allowed), the TX40 record's fit and the timings."""

    regs: Regressors
    measured: Measured
    fits: Fits
    val: Validation
    friction: dict[str, Any]
    hac: HacCovariance
    white_sigma: np.ndarray
    truth: dict[str, Any] | None
    tx: Tx40Result | None
    timings: dict[str, float]


def identified_friction(p: np.ndarray, nq: int, stribeck: StribeckFit | None = None,
                        load: LoadFriction | None = None) -> JointFriction:
    """The friction handed on: viscous and Coulomb from the standard parameters ``p``, the Stribeck
    term from ``stribeck`` (``friction_model: stribeck``; else none), the load-dependent Coulomb
    coefficient from ``load`` (when the held-out data chose it; else none)."""
    layout = DynamicLayout(nq)
    return JointFriction(p[layout.viscous].copy(), p[layout.coulomb].copy(),
                         None if stribeck is None else stribeck.static_excess_Nm.copy(),
                         None if stribeck is None else stribeck.stribeck_velocity_rad_s.copy(),
                         None if load is None else load.coefficient.copy())


def identified_robot(robot: RobotModel, p: np.ndarray, stribeck: StribeckFit | None = None,
                     load: LoadFriction | None = None, coulomb_width_rad_s: np.ndarray | None = None) -> RobotModel:
    """Copy of ``robot`` with the standard parameters ``p`` (inertias, rotor inertia, viscous and
    Coulomb friction; torque offsets are not part of a RobotModel) and, with a Stribeck fit, its
    static excess and Stribeck velocity (``friction_model: stribeck``; else none), with a
    load-dependent term its coefficient (all joints, 0 where none); ``coulomb_width_rad_s`` (nq,): the
    Coulomb smoothing widths the fits used (None: ``robot``'s). A link whose fitted principal moments fall
    under the floor that loading a robot keeps (:func:`pipeline.robot.vendor_urdf.consistent_inertia`,
    1e-6 kg m²; a physically consistent fit can end a little below it) gets the loader's smallest change, so
    the robot handed on is the one read back."""
    nq = robot.nq
    model = set_dynamic_parameters(robot.model, p)
    for j in range(1, model.njoints):        # a fit's moments a hair under the loader's floor: as read back
        change = consistent_inertia(model.inertias[j])
        if change is not None:
            model.inertias[j] = change[2]
    spec = copy.deepcopy(robot.spec)
    off = 10 * (robot.model.njoints - 1)
    spec.actuation.rotor_inertia_kgm2 = p[off : off + nq].copy()
    identified_friction(p, nq, stribeck, load).apply_to(spec.actuation)
    if coulomb_width_rad_s is not None:
        spec.actuation.coulomb_smoothing_rad_s = np.asarray(coulomb_width_rad_s, float).copy()
    return robot.with_model(model, spec)
