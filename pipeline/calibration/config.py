"""Configuration of stage ``calibration`` (section ``calibration:`` of the run YAML).

Robot-independent checks in :meth:`Config.validate` (called at load time); the ones that need the
robot (the number of identifiable parameters, the tracker's incidence limit) in
:func:`pipeline.calibration.stage.check`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pipeline.calibration import indices as ix
from pipeline.calibration.task_space import check_task_fields
from pipeline.errors import ConfigError

SELECTION_METHODS = ("remove_and_replace", "detmax", "bsaa", "random", "gradient")
CANDIDATE_KINDS = ("grid", "random")
ERROR_MODELS = ("se3", "mdh_hayati")
#: indices the gradient design (IPOPT) can optimise
GRADIENT_INDICES = ix.TRACE_INDICES
#: largest candidate set (random candidates or grid points): beyond it the filtering and the
#: whitened Jacobians of the feasible candidates take too much time and memory
MAX_CANDIDATES = 20_000_000


@dataclass
class Config:
    """Settings of the calibration stage (defaults = the full profile)."""

    #: "grid" (``grid_per_axis`` values per axis, paper 004: 13) or "random"
    candidates: str = "grid"
    grid_per_axis: int = 13
    n_random_candidates: int = 20000
    #: remove_and_replace | detmax | bsaa | random | gradient (remove-and-replace + IPOPT refinement)
    selection_method: str = "remove_and_replace"
    #: O1..O5, D, A, E, Od, Oc, tcp_A, tcp_A_mixed, V (see pipeline.calibration.indices); V: the
    #: predicted TCP variance over the working region (pipeline.calibration.task_space)
    index_name: str = "V"
    n_configurations: int = 50
    #: initial subset size of remove-and-replace (None: 2/3 of n_configurations)
    n_initial: int | None = None
    #: working configurations for the TCP-covariance criterion (random feasible poses)
    n_working_configurations: int = 5
    #: "se3": 6 errors per joint placement + zero offsets; "mdh_hayati": modified DH + Hayati beta
    error_model: str = "se3"
    identifiability_samples: int = 200
    identifiability_rel_tol: float = 1e-7
    n_heldout: int = 1000
    margin_collision_m: float = 0.01
    margin_incidence_deg: float = 3.0
    margin_beam_m: float = 0.02
    max_lm_iterations: int = 50
    gradient_max_iterations: int = 200
    #: gradient design only: random configurations measured first to register the tracker pose
    #: (visibility constraints need it); they count towards n_configurations and are used in the fit
    n_pilot: int = 8
    #: user data instead of the simulated tracker (format: pipeline.calibration.measure)
    measurements_csv: str | None = None
    validation_csv: str | None = None
    figures: bool = True
    # -- task-space criterion and design table (pipeline.calibration.task_space, design_table) --
    #: iso_cube (control.iso) | box (working_box_m) | csv (working_csv: columns q1..qn, rad)
    working_region: str = "iso_cube"
    working_box_m: list[list[float]] | None = None
    working_csv: str | None = None
    #: working configurations sampled in the region (W of the V criterion)
    n_region_configurations: int = 300
    #: compare the design with baselines of the same size in the report (predicted TCP RMS; in
    #: simulation also measured on design_table_heldout visible poses of the working region)
    design_table: bool = True
    design_table_heldout: int = 300

    def validate(self, source: str = "config") -> None:
        """Robot-independent checks of every field (robot-dependent ones: :func:`check`)."""
        def bad(key: str, problem: str) -> ConfigError:
            return ConfigError(source, f"calibration.{key}", problem)

        if self.candidates not in CANDIDATE_KINDS:
            raise bad("candidates", f"must be one of {CANDIDATE_KINDS}, got {self.candidates!r}")
        if self.selection_method not in SELECTION_METHODS:
            raise bad("selection_method", f"must be one of {SELECTION_METHODS}, got {self.selection_method!r}")
        if self.index_name not in ix.INDEX_NAMES:
            raise bad("index_name", f"must be one of {ix.INDEX_NAMES}, got {self.index_name!r}")
        if self.error_model not in ERROR_MODELS:
            raise bad("error_model", f"must be one of {ERROR_MODELS}, got {self.error_model!r}")
        for key in ("grid_per_axis", "n_random_candidates", "n_configurations", "n_heldout",
                    "identifiability_samples", "max_lm_iterations", "n_working_configurations",
                    "gradient_max_iterations"):
            if getattr(self, key) < 1:
                raise bad(key, f"must be >= 1, got {getattr(self, key)}")
        if self.grid_per_axis < 2:
            raise bad("grid_per_axis", f"needs at least 2 values per axis, got {self.grid_per_axis}")
        if self.identifiability_samples > 100_000:
            raise bad("identifiability_samples",
                      f"at most 100000 (the default 200 suffice), got {self.identifiability_samples}")
        if self.n_random_candidates > MAX_CANDIDATES:
            raise bad("n_random_candidates", f"at most {MAX_CANDIDATES} (memory of the candidate Jacobians), "
                      f"got {self.n_random_candidates}")
        if (self.candidates == "random" and not self.measurements_csv
                and self.n_random_candidates < self.n_configurations):
            raise bad("n_random_candidates", f"{self.n_random_candidates} feasible random candidates cannot "
                      f"give n_configurations = {self.n_configurations} distinct configurations; give at least "
                      f"{self.n_configurations} (many more for a good selection; quick profile 1500)")
        if self.n_initial is not None and not 1 <= self.n_initial <= self.n_configurations:
            raise bad("n_initial", f"must be in [1, n_configurations = {self.n_configurations}] or null "
                      f"(2/3 of n_configurations), got {self.n_initial}")
        if self.n_pilot < 0:
            raise bad("n_pilot", f"must be >= 0 (0: no pilot measurements), got {self.n_pilot}")
        if self.selection_method == "gradient":
            if 0 < self.n_pilot < 3:
                raise bad("n_pilot", f"must be 0 (nominal tracker pose) or >= 3 (registering the tracker "
                          f"pose needs 3 points), got {self.n_pilot}")
            if self.n_pilot >= self.n_configurations:
                raise bad("n_pilot", f"the pilot measurements count towards n_configurations = "
                          f"{self.n_configurations}: must be smaller, got {self.n_pilot}")
        tol = self.identifiability_rel_tol
        if not (math.isfinite(tol) and 0 < tol < 1):
            raise bad("identifiability_rel_tol", f"must be in (0, 1) (relative singular value), got {tol}")
        for key in ("margin_collision_m", "margin_beam_m"):
            v = getattr(self, key)
            if not (math.isfinite(v) and 0 <= v < 1):
                raise bad(key, f"must be in [0, 1) m (a clearance in metres), got {v}")
        v = self.margin_incidence_deg
        if not (math.isfinite(v) and 0 <= v < 90):
            raise bad("margin_incidence_deg", f"must be in [0, 90) degrees, got {v}")
        check_task_fields(self, source)
        if self.selection_method == "gradient" and self.index_name not in GRADIENT_INDICES:
            raise bad("selection_method", f"gradient optimises an A-type index (calibration.index_name one of "
                      f"{GRADIENT_INDICES}), but index_name is {self.index_name!r}")
