"""Scenario sweeps: one task run over many seeded scenarios, judged by statistics.

A sweep definition (`spec.SweepSpec`: task, robot, seed, scenarios, varied keys with their
distributions, task parameters) is sampled scenario by scenario (`sampling`), each scenario's values
depending only on (seed, index); each scenario is one deterministic run (`worker`), run on local
cores or a Dask cluster (`executors`); the rows become `results.parquet` and `summary.json`
(`results`, `stats`), and a stored definition with its summary is a statistical golden (`golden`).
This package sits above `verify` (it imports tasks, sim, record and verify); only `cli` imports it.
"""
