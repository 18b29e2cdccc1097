"""The predictive (MPC) safety filter, as a package: settings, plan model, NLP and its solvers, filter.

==============  ================================================================
module          what it owns
==============  ================================================================
``config``      :class:`MPCConfig`, the solvers the filter can use
``plan``        :class:`PlanLayout` (which commands are chosen), :class:`BaseModel` (how the
                base follows commands), :class:`MPCProblem`, checks
``nlp``         casadi: the plan model and its Jacobian (:class:`PlanModel`), the reference NLP
``sqp``         the NLP (:class:`PlanNLP`) and its fast solver (:class:`DirectSQP`)
``filter``      :class:`MPCSafetyFilter`
==============  ================================================================
"""

from safenav.filters.mpc.config import MPCConfig, available_mpc_solvers
from safenav.filters.mpc.filter import MPCSafetyFilter
from safenav.filters.mpc.nlp import CasadiNLP, PlanModel
from safenav.filters.mpc.plan import BaseModel, MPCProblem, PlanCheck, PlanLayout
from safenav.filters.mpc.sqp import DirectSQP, NLPOutcome, PlanCost, PlanNLP, PlanSolver

__all__ = [
    "BaseModel",
    "CasadiNLP",
    "DirectSQP",
    "MPCConfig",
    "MPCProblem",
    "MPCSafetyFilter",
    "NLPOutcome",
    "PlanCheck",
    "PlanCost",
    "PlanLayout",
    "PlanModel",
    "PlanNLP",
    "PlanSolver",
    "available_mpc_solvers",
]
