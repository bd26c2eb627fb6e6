"""Scenario sweeps: one task run over many seeded scenarios, judged by statistics.

A sweep definition (`spec.SweepSpec`: task, robot, seed, scenarios, varied keys with their
distributions, task parameters) is sampled scenario by scenario (`sampling`), each scenario's values
depending only on (seed, index); each scenario is one deterministic run (`worker`; `worker.Job` is
the sweep's unit of work), fanned out on local cores or a Dask cluster by `twin.jobs` (`runner`,
`folder`); the rows become `results.parquet` and `summary.json`
(`results`, `stats`), and a stored definition with its summary is a statistical golden (`golden`).
This package sits above `verify` (it imports tasks, sim, record, jobs and verify); `search` and
`cli` import it.
"""
