"""Where the solver stops: the named IPOPT settings of :class:`.ipopt.SolverOptions` (``stop``).

A module of its own, without imports, so that the command line can offer the names without
loading the solver (``docs/solver.md``, "Where the solver stops").
"""

__all__ = ["STOPS", "DEFAULT_STOP"]

#: Where IPOPT stops: the IPOPT options of each named stop (``SolverOptions.stop``;
#: ``docs/solver.md``, "Where the solver stops"). ``optimum``: the optimum of the stated problem
#: (IPOPT's adaptive barrier globalised by the KKT error: the rates within 0.15 % of those at
#: tolerance 1e-10 on the example subject's six units and both legs of gait2392, in fewer
#: iterations than ``authors`` on the example subject); ``authors``: the settings of
#: Luis et al. (2024), whose stop leaves the activations of muscles that are off up to 0.02
#: above zero and the rates 4-18 % above the optimum's.
STOPS = {
    "optimum": {"tol": 1e-8, "mu_strategy": "adaptive", "adaptive_mu_globalization": "kkt-error"},
    "authors": {"tol": 1e-6, "mu_strategy": "monotone"},
}
DEFAULT_STOP = "optimum"
