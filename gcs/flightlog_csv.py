"""The self-describing CSV of a FlightLog: ``save_timeseries`` / ``load_timeseries`` round-trip
exactly (floats are written with ``repr``, the shortest string that reads back bit for bit).

CSV format (``TIMESERIES_FORMAT``)::

    # formation-flight-timeseries/1
    # meta: {"name": ..., "source": ..., "controller": ..., "team": ..., "vehicle_ids": [...],
    #        "sysids": [...], "offsets_enu_m": [[...], ...], "n_samples": k, "extra": {...}}
    t_s,vehicle_id,x_enu_m,y_enu_m,z_enu_m,vx_enu_mps,...,fz_enu_n
    0.0,1,4.0,4.0,9.0,...

One row per sample and vehicle, sample-major (all vehicles of sample 0, then sample 1, ...).
Metadata is one JSON object on the line starting with ``# meta: ``. The reference velocity is
repeated on every vehicle row of its sample. Missing values are written ``nan``. Readers other than
``load_timeseries`` can skip the ``#`` lines (``pandas.read_csv(path, comment="#")``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from gcs.flightlog import SERIES_SHAPES, FlightLog

TIMESERIES_FORMAT = "formation-flight-timeseries/1"
#: CSV data columns after ``t_s,vehicle_id``: (column name, FlightLog field, component or None).
CSV_COLUMNS: tuple[tuple[str, str, int | None], ...] = (
    ("x_enu_m", "position_enu_m", 0),
    ("y_enu_m", "position_enu_m", 1),
    ("z_enu_m", "position_enu_m", 2),
    ("vx_enu_mps", "velocity_enu_mps", 0),
    ("vy_enu_mps", "velocity_enu_mps", 1),
    ("vz_enu_mps", "velocity_enu_mps", 2),
    ("vrx_enu_mps", "reference_velocity_enu_mps", 0),
    ("vry_enu_mps", "reference_velocity_enu_mps", 1),
    ("vrz_enu_mps", "reference_velocity_enu_mps", 2),
    ("attitude_error", "attitude_error", None),
    ("omega_error_radps", "omega_error_radps", None),
    ("mass_estimate_kg", "mass_estimate_kg", None),
    ("mass_true_kg", "mass_true_kg", None),
    ("jx_estimate_kgm2", "inertia_estimate_kgm2", 0),
    ("jy_estimate_kgm2", "inertia_estimate_kgm2", 1),
    ("jz_estimate_kgm2", "inertia_estimate_kgm2", 2),
    ("thrust_n", "thrust_n", None),
    ("fx_enu_n", "force_enu_n", 0),
    ("fy_enu_n", "force_enu_n", 1),
    ("fz_enu_n", "force_enu_n", 2),
)
CSV_HEADER: tuple[str, ...] = ("t_s", "vehicle_id", *(c[0] for c in CSV_COLUMNS))


def _json_default(obj: object) -> object:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"FlightLog.extra: value of type {type(obj).__name__} is not JSON-compatible")


def save_timeseries(log: FlightLog, path: str | os.PathLike[str]) -> Path:
    """Write ``log`` as the CSV described in the module docstring; returns the path when written.

    The file is written to a temporary name and renamed, so a reader never sees half a file.
    Raises TypeError if ``log.extra`` holds a value JSON cannot encode.
    """
    path = Path(path)
    k, n = log.n_samples, log.n_vehicles
    meta = {
        "name": log.name,
        "source": log.source,
        "controller": log.controller,
        "team": log.team,
        "vehicle_ids": log.vehicle_ids.tolist(),
        "sysids": log.sysids.tolist(),
        "offsets_enu_m": log.offsets_enu_m.tolist(),
        "n_samples": k,
        "extra": log.extra,
    }
    meta_line = json.dumps(meta, default=_json_default, separators=(", ", ": "))
    if "\n" in meta_line or "\r" in meta_line:  # json escapes newlines in strings; be sure
        raise ValueError("FlightLog metadata must encode on one line")

    columns = []
    for _, name, comp in CSV_COLUMNS:
        a = getattr(log, name)
        if name == "reference_velocity_enu_mps":
            a = np.broadcast_to(a[:, None, :], (k, n, 3))
        columns.append(a[..., comp] if comp is not None else a)
    data = np.stack(columns, axis=-1).reshape(k * n, len(CSV_COLUMNS)).tolist()
    t_col = np.repeat(log.t_s, n).tolist()
    id_col = np.tile(log.vehicle_ids, k).tolist()

    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", encoding="utf-8", newline="") as f:
        f.write(f"# {TIMESERIES_FORMAT}\n")
        f.write(f"# meta: {meta_line}\n")
        f.write(",".join(CSV_HEADER) + "\n")
        rep = float.__repr__
        f.writelines(
            f"{rep(t)},{vid},{','.join(map(rep, row))}\n"
            for t, vid, row in zip(t_col, id_col, data, strict=True)
        )
    os.replace(tmp, path)
    return path


def load_timeseries(path: str | os.PathLike[str]) -> FlightLog:
    """Read a CSV written by ``save_timeseries`` back into a FlightLog (bit-exact floats).

    Rows may come in any order; each sample must have exactly one row per vehicle of the metadata,
    with the same reference velocity on each. Raises ValueError naming the file and the problem.
    """
    path = Path(path)
    with path.open("r", encoding="utf-8", newline="") as f:
        lines = f.read().splitlines()
    if not lines or lines[0].strip() != f"# {TIMESERIES_FORMAT}":
        raise ValueError(f"{path}: not a {TIMESERIES_FORMAT} file (first line {lines[:1]!r})")
    meta: dict[str, Any] | None = None
    i = 1
    while i < len(lines) and lines[i].startswith("#"):
        if lines[i].startswith("# meta: "):
            meta = json.loads(lines[i][len("# meta: ") :])
        i += 1
    if meta is None:
        raise ValueError(f"{path}: missing the '# meta: {{...}}' line")
    if i >= len(lines):
        raise ValueError(f"{path}: missing the column header line")
    header = [h.strip() for h in lines[i].split(",")]
    missing = [c for c in CSV_HEADER if c not in header]
    if missing:
        raise ValueError(f"{path}: missing columns {missing}")
    body = [ln for ln in lines[i + 1 :] if ln.strip()]

    ids = np.asarray(meta["vehicle_ids"], dtype=np.int64)
    n = ids.size
    k = int(meta["n_samples"])
    if len(body) != k * n:
        raise ValueError(
            f"{path}: expected {k} samples x {n} vehicles = {k * n} rows, got {len(body)}"
        )
    table = np.loadtxt(body, delimiter=",", dtype=np.float64, ndmin=2)
    if table.shape[1] != len(header):
        raise ValueError(f"{path}: expected {len(header)} columns per row, got {table.shape[1]}")
    col = {name: table[:, header.index(name)] for name in CSV_HEADER}

    position = {int(v): j for j, v in enumerate(ids)}
    row_ids = col["vehicle_id"]
    unknown = sorted({int(v) for v in row_ids} - set(position))
    if unknown:
        raise ValueError(f"{path}: rows for vehicles {unknown} not in vehicle_ids {ids.tolist()}")
    vpos = np.array([position[int(v)] for v in row_ids], dtype=np.intp)
    order = np.lexsort((vpos, col["t_s"]))
    t_grid = col["t_s"][order].reshape(k, n)
    if not np.all(t_grid == t_grid[:, :1]) or not np.all(vpos[order].reshape(k, n) == np.arange(n)):
        raise ValueError(
            f"{path}: every sample must have exactly one row per vehicle {ids.tolist()}"
        )

    series: dict[str, np.ndarray] = {}
    for name, tail in SERIES_SHAPES.items():
        comps = [c for c in CSV_COLUMNS if c[1] == name]
        a = np.stack([col[c[0]][order] for c in comps], axis=-1).reshape(k, n, len(comps))
        if name == "reference_velocity_enu_mps":
            same = (a == a[:, :1]) | (np.isnan(a) & np.isnan(a[:, :1]))
            if not np.all(same):
                bad = int(np.flatnonzero(~same.all(axis=(1, 2)))[0])
                raise ValueError(
                    f"{path}: reference velocity differs between vehicles at t_s = "
                    f"{float(t_grid[bad, 0])!r}"
                )
            a = a[:, 0, :]
        elif len(tail) == 1:
            a = a[..., 0]
        series[name] = a
    return FlightLog(
        t_s=t_grid[:, 0],
        **series,
        vehicle_ids=ids,
        sysids=np.asarray(meta["sysids"], dtype=np.int64),
        offsets_enu_m=np.asarray(meta["offsets_enu_m"], dtype=np.float64),
        source=meta["source"],
        controller=meta["controller"],
        team=meta["team"],
        name=meta["name"],
        extra=meta.get("extra") or {},
    )
