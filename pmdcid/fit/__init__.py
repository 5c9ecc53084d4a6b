"""The one fit engine: a parameter set, the simulation-error problem, the solver, covariances,
priors and the result types. Every fit of pmdcid goes through it (docs/architecture.md)."""
