"""The predictive (MPC) safety filter, as a package: settings, plan model, NLP, filter.

==============  ================================================================
module          what it owns
==============  ================================================================
``config``      :class:`MPCConfig`, the solvers casadi offers here
``plan``        :class:`BaseModel` (how the base follows commands), :class:`MPCProblem`, checks
``nlp``         the casadi NLP, built once per shape, and its solver back-end
``filter``      :class:`MPCSafetyFilter`
==============  ================================================================
"""

from safenav.filters.mpc.config import MPCConfig, available_mpc_solvers
from safenav.filters.mpc.filter import MPCSafetyFilter
from safenav.filters.mpc.nlp import CasadiBackend, SolveOutcome
from safenav.filters.mpc.plan import BaseModel, MPCProblem, PlanCheck

__all__ = [
    "BaseModel",
    "CasadiBackend",
    "MPCConfig",
    "MPCProblem",
    "MPCSafetyFilter",
    "PlanCheck",
    "SolveOutcome",
    "available_mpc_solvers",
]
