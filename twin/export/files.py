"""A recording's frames, events or commands as one Parquet or CSV file (columns: record.tables).

Written beside the target as NAME.partial and renamed over it when complete, like recordings.
"""

from __future__ import annotations

from pathlib import Path

from twin.model.recording import Recording
from twin.record.outputs import partial_path, publish

FORMATS = {"parquet": ".parquet", "csv": ".csv"}


def write_table(rec: Recording, path: Path, fmt: str, table: str = "frames") -> int:
    """Write one of rec's tables ("frames", "events", "commands") to path as fmt; returns its
    rows."""
    import pyarrow.csv as pa_csv
    import pyarrow.parquet as pq

    data = rec.to_arrow(table)
    partial = partial_path(path)
    try:
        if fmt == "parquet":
            pq.write_table(data, partial, compression="zstd")
        else:
            pa_csv.write_csv(data, partial)
        publish(partial, path)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    return data.num_rows
