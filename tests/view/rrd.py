"""Read a .rrd back with rerun-sdk 0.41's ``rerun.chunk.RrdReader`` (``rerun.dataframe`` is gone).

``read_recording`` groups the chunks of the file's recording by entity path; each entity's
temporal rows are concatenated in logging order (by row id), its static rows kept apart.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
from rerun.chunk import RrdReader

ROW_ID = "rerun.controls.RowId"


@dataclass(frozen=True)
class Entity:
    rows: pa.Table  # temporal rows, in logging order
    static: pa.Table | None

    def __len__(self) -> int:
        return self.rows.num_rows

    def column(self, name: str) -> list[Any]:
        """A component (e.g. ``Scalars:scalars``) or timeline (``cycle``) column as Python values."""
        return self.rows.column(name).to_pylist()

    def static_column(self, name: str) -> list[Any]:
        assert self.static is not None, "no static data at this entity"
        return self.static.column(name).to_pylist()


def read_recording(path: str | Path) -> dict[str, Entity]:
    """Entity path (e.g. ``/robot/scan``) -> its rows, for the first recording in the file."""
    temporal: dict[str, list[pa.Table]] = {}
    static: dict[str, list[pa.Table]] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        table = pa.Table.from_batches([chunk.to_record_batch()])
        (static if chunk.is_static else temporal).setdefault(chunk.entity_path, []).append(table)
    out: dict[str, Entity] = {}
    for entity in temporal.keys() | static.keys():
        rows = _concat(temporal.get(entity, []))
        fixed = _concat(static[entity]) if entity in static else None
        out[entity] = Entity(rows, fixed)
    return out


def _concat(tables: list[pa.Table]) -> pa.Table:
    if not tables:
        return pa.table({})
    plain = [t.replace_schema_metadata(None) for t in tables]
    merged = pa.concat_tables(plain, promote_options="default")
    order = sorted(range(merged.num_rows), key=merged.column(ROW_ID).to_pylist().__getitem__)
    return merged.take(order)
