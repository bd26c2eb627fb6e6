"""`twin search`: the smallest perturbation that breaks a task and the boundary along each key
(`search`), the keys and ranges it searches (`keys`), and a failure it found kept as a regression
test (`golden`). It builds on `sweep` (a search's run is a one-scenario sweep) and fans its rounds
out through `jobs`; only `cli` imports it."""
