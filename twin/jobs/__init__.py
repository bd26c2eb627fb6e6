"""Fanning work out: one way for `twin sweep`, `twin search` and `twin check -j N`.

The work is a `unit.Unit` (warm up, run an item, confirm an item whose first run died, a failed
item's result), handed by the layer above; `executors` runs it on this machine's cores
(`LocalExecutor`, children forked and watched by `guard.GuardedPool`) or on Dask (`DaskExecutor`,
`cluster`). Whatever the executor: a worker that dies is replaced and its item, run once more alone,
is named as failed; Ctrl-C and SIGTERM stop the workers at once, the results so far kept by the
caller; a `kill -9` of the parent takes its children along (PR_SET_PDEATHSIG).
This package imports only `model`, `helpers` and `signals`: it knows nothing of sweeps or goldens.
"""
