"""tolsynth: optimal manufacturing tolerances for robot link parameters.

Chooses the cheapest tolerances ``eps_i`` for a robot's link parameters such that its absolute
pose error stays within a specification with a stated probability (Xu Weiliang and Zhang Qixian,
"Precision optimization design of robot mechanisms", 1988), on CasADi graphs with IPOPT, and
with the paper's own SUMT + Powell method as a cross-check.

Units: mm and rad throughout the API; tolerances in each error parameter's own unit (the paper's:
mm and 1e-2 rad); cost in the paper's units (sum of k * eps**-alpha on those numbers).
"""

from tolsynth.interrupts import guard_start as _guard_start

_guard_start()  # noqa: E702,I001  (Ctrl-C while the command starts: one line)
from tolsynth.analysis.certify import Certificate, certify_worst_pose
from tolsynth.analysis.certify_map import CertifiedMap, certified_map
from tolsynth.analysis.contributions import Contributions, contributions
from tolsynth.analysis.interval_arb import EnclosureCheck, check_certificate_enclosures
from tolsynth.analysis.montecarlo import MonteCarloResult, monte_carlo
from tolsynth.analysis.plot import plot_map
from tolsynth.analysis.pose_search import WorstPose, worst_pose
from tolsynth.analysis.validation import ValidationResult, validate
from tolsynth.analysis.verify import Verification
from tolsynth.analysis.workspace_map import ProbabilityMap, probability_map
from tolsynth.errors import (
    InfeasibleSpecificationError,
    InputError,
    LoopClosureError,
    MissingDependencyError,
    ModelFileError,
    OutOfRangeError,
    SolverError,
    TolsynthError,
    UnknownNameError,
    UnsupportedJointError,
)
from tolsynth.io.reports import DesignReport, report
from tolsynth.io.tables import read_table, write_table
from tolsynth.kinematics.mechanism import Analysis, Mechanism, load_model, load_urdf
from tolsynth.model.joint_errors import JointError
from tolsynth.model.reader import bundled_models
from tolsynth.probability.exact import (
    ExactProbabilityError,
    ball_probability,
    cone_probability,
    direction_probability,
    direction_probability_batch,
    worst_direction,
)
from tolsynth.probability.stats import p_ball, p_components, p_cone, z_of_p
from tolsynth.problem.result import Status, SynthesisResult
from tolsynth.synthesis.budget import BudgetResult, best_accuracy
from tolsynth.synthesis.compare import Comparison, compare
from tolsynth.synthesis.grades import GradeChoice, round_to_grades
from tolsynth.synthesis.options import DesignSpec, SolverOptions
from tolsynth.synthesis.pareto import ParetoFront, pareto_front
from tolsynth.synthesis.processes import Process, ProcessChoice, synthesize_processes
from tolsynth.synthesis.single import synthesize
from tolsynth.synthesis.sweeps import sweep
from tolsynth.synthesis.workspace import WorkspaceSynthesis, synthesize_workspace
from tolsynth.version import __version__  # noqa: F401  (the package version, as tolsynth.__version__)

__all__ = [
    "DesignSpec",
    "SolverOptions",
    "direction_probability",
    "direction_probability_batch",
    "ball_probability",
    "cone_probability",
    "worst_direction",
    "ExactProbabilityError",
    "Verification",
    "contributions",
    "Contributions",
    "synthesize_processes",
    "round_to_grades",
    "GradeChoice",
    "best_accuracy",
    "BudgetResult",
    "pareto_front",
    "ParetoFront",
    "Process",
    "ProcessChoice",
    "monte_carlo",
    "MonteCarloResult",
    "validate",
    "ValidationResult",
    "worst_pose",
    "WorstPose",
    "certify_worst_pose",
    "Certificate",
    "certified_map",
    "CertifiedMap",
    "check_certificate_enclosures",
    "EnclosureCheck",
    "probability_map",
    "ProbabilityMap",
    "plot_map",
    "load_model",
    "synthesize",
    "synthesize_workspace",
    "WorkspaceSynthesis",
    "compare",
    "Comparison",
    "SynthesisResult",
    "Status",
    "bundled_models",
    "Mechanism",
    "Analysis",
    "z_of_p",
    "p_ball",
    "p_components",
    "p_cone",
    "TolsynthError",
    "InputError",
    "UnknownNameError",
    "OutOfRangeError",
    "ModelFileError",
    "LoopClosureError",
    "InfeasibleSpecificationError",
    "SolverError",
    "MissingDependencyError",
    "read_table",
    "write_table",
    "sweep",
    "JointError",
    "report",
    "DesignReport",
    "load_urdf",
    "UnsupportedJointError",
]
