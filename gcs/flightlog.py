"""The time series of one formation flight (sim or fly): the FlightLog record, its builder, CSV I/O.

Frames and units: every vector is in the app's world frame ENU (x east, y north, z up; the paper's
frame), SI units as the field suffixes say. ``t_s = 0`` is the start of the formation phase.
Shapes: ``k`` samples, ``n`` vehicles.

* ``FlightLog`` is frozen; its arrays are read-only float64 (ids and sysids int64) copies.
* ``FlightLog.from_arrays`` makes one from whole arrays (the simulation);
  ``FlightLogBuilder`` appends one sample at a time (``gcs fly``) and ``build()``s it.
* ``save_timeseries`` / ``load_timeseries`` write and read a self-describing CSV that round-trips
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
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gcs.metrics import grid_indices

TIMESERIES_FORMAT = "formation-flight-timeseries/1"
SOURCES = ("sim", "fly")
#: no law ran: the vehicles' own position controllers flew their formation slots (gcs fly's
#: position mode, gcs/control/slots.py)
AUTOPILOT_CONTROLLER = "autopilot"
CONTROLLERS = ("adaptive", "baseline", AUTOPILOT_CONTROLLER)

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

#: Per-sample series: field name -> shape after the leading k ("n" = number of vehicles).
SERIES_SHAPES: dict[str, tuple[str | int, ...]] = {
    "position_enu_m": ("n", 3),
    "velocity_enu_mps": ("n", 3),
    "reference_velocity_enu_mps": (3,),
    "attitude_error": ("n",),
    "omega_error_radps": ("n",),
    "mass_estimate_kg": ("n",),
    "mass_true_kg": ("n",),
    "inertia_estimate_kgm2": ("n", 3),
    "thrust_n": ("n",),
    "force_enu_n": ("n", 3),
}


def _shape_str(shape: Sequence[str | int]) -> str:
    return "(" + ", ".join(str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, slots=True, eq=False)
class FlightLog:
    """The recorded time series of one flight; k samples, n vehicles, world frame ENU.

    Per-sample series (float64; NaN allowed where a value was not available, e.g. a lost
    telemetry sample, except in ``t_s``):
      t_s (k,)                          sample times [s], strictly increasing, 0 = formation start
      position_enu_m (k, n, 3)          p_i [m]
      velocity_enu_mps (k, n, 3)        v_i [m/s]
      reference_velocity_enu_mps (k, 3) v_r [m/s]
      attitude_error (k, n)             tr(I - R_i^e), dimensionless, 0..4
      omega_error_radps (k, n)          |omega_i^e| [rad/s]
      mass_estimate_kg (k, n)           alpha_m mhat_i / phi_i [kg] (what converges to m_i)
      mass_true_kg (k, n)               true mass [kg], NaN where unknown (e.g. real vehicles)
      inertia_estimate_kgm2 (k, n, 3)   (Jx, Jy, Jz) estimate rhohat_i [kg m^2]
      thrust_n (k, n)                   commanded collective thrust T_i [N]
      force_enu_n (k, n, 3)             command force u_i [N]
    Static metadata: vehicle_ids (n,) and sysids (n,) ints, offsets_enu_m (n, 3) theta_i [m],
    source "sim" | "fly", controller "adaptive" | "baseline" | "autopilot" (no law: gcs fly's
    position mode; its estimates, thrust, force and attitude errors are NaN), team (config
    path), name, and
    ``extra``: a JSON-compatible dict of per-run figures (e.g. ``{"link": ..., "tick": ...}``).
    The figures read from it (absent in older logs): ``mode`` ("actuators" | "rates" |
    "attitude" | "position"), ``estimates`` (``estimates_record``) and, from gcs fly,
    ``vehicle_kinds`` (one line per vehicle, e.g. "PX4 (vehicle-emu px4)").
    """

    t_s: np.ndarray
    position_enu_m: np.ndarray
    velocity_enu_mps: np.ndarray
    reference_velocity_enu_mps: np.ndarray
    attitude_error: np.ndarray
    omega_error_radps: np.ndarray
    mass_estimate_kg: np.ndarray
    mass_true_kg: np.ndarray
    inertia_estimate_kgm2: np.ndarray
    thrust_n: np.ndarray
    force_enu_n: np.ndarray
    vehicle_ids: np.ndarray
    sysids: np.ndarray
    offsets_enu_m: np.ndarray
    source: str
    controller: str
    team: str
    name: str
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        def put(name: str, value: object) -> None:
            object.__setattr__(self, name, value)

        t = np.array(self.t_s, dtype=np.float64)
        if t.ndim != 1 or t.size == 0:
            raise ValueError(f"FlightLog.t_s: expected shape (k,) with k >= 1, got {t.shape}")
        if not np.all(np.isfinite(t)):
            bad = int(np.flatnonzero(~np.isfinite(t))[0])
            raise ValueError(f"FlightLog.t_s: sample {bad} is not finite ({float(t[bad])})")
        steps = np.diff(t)
        if np.any(steps <= 0.0):
            bad = int(np.flatnonzero(steps <= 0.0)[0]) + 1
            raise ValueError(
                f"FlightLog.t_s: expected strictly increasing times, got t_s[{bad}] = "
                f"{float(t[bad])!r} after t_s[{bad - 1}] = {float(t[bad - 1])!r}"
            )
        k = t.size
        put("t_s", _readonly(t))

        ids = np.array(self.vehicle_ids)
        if ids.ndim != 1 or ids.size == 0:
            raise ValueError(
                f"FlightLog.vehicle_ids: expected shape (n,) with n >= 1, got {ids.shape}"
            )
        n = ids.size
        put("vehicle_ids", _readonly(self._ints("vehicle_ids", ids)))
        if len(set(self.vehicle_ids.tolist())) != n:
            raise ValueError(f"FlightLog.vehicle_ids: expected unique ids, got {ids.tolist()}")
        sysids = np.array(self.sysids)
        if sysids.shape != (n,):
            raise ValueError(f"FlightLog.sysids: expected shape ({n},), got {sysids.shape}")
        put("sysids", _readonly(self._ints("sysids", sysids)))
        offsets = np.array(self.offsets_enu_m, dtype=np.float64)
        if offsets.shape != (n, 3):
            raise ValueError(
                f"FlightLog.offsets_enu_m: expected shape ({n}, 3), got {offsets.shape}"
            )
        if not np.all(np.isfinite(offsets)):
            raise ValueError(
                f"FlightLog.offsets_enu_m: expected finite values, got {offsets.tolist()}"
            )
        put("offsets_enu_m", _readonly(offsets))

        for name, tail in SERIES_SHAPES.items():
            a = np.array(getattr(self, name), dtype=np.float64)
            expected = (k, *(n if s == "n" else s for s in tail))
            if a.shape != expected:
                raise ValueError(
                    f"FlightLog.{name}: expected shape {_shape_str(('k', *tail))} = {expected} "
                    f"for k={k} samples and n={n} vehicles, got {a.shape}"
                )
            put(name, _readonly(a))

        for name, allowed in (("source", SOURCES), ("controller", CONTROLLERS)):
            if getattr(self, name) not in allowed:
                raise ValueError(
                    f"FlightLog.{name}: expected one of {allowed}, got {getattr(self, name)!r}"
                )
        for name in ("team", "name"):
            if not isinstance(getattr(self, name), str):
                raise ValueError(
                    f"FlightLog.{name}: expected str, got {type(getattr(self, name)).__name__}"
                )
        if not isinstance(self.extra, Mapping):
            raise ValueError(f"FlightLog.extra: expected a dict, got {type(self.extra).__name__}")
        put("extra", dict(self.extra))

    @staticmethod
    def _ints(name: str, a: np.ndarray) -> np.ndarray:
        if a.dtype.kind in "iu":
            return a.astype(np.int64)
        if a.dtype.kind == "f" and np.all(np.isfinite(a)) and np.all(a == np.round(a)):
            return a.astype(np.int64)
        raise ValueError(f"FlightLog.{name}: expected integers, got {a.tolist()}")

    # ----------------------------------------------------------------------------------------------
    @classmethod
    def from_arrays(
        cls,
        *,
        t_s: Any,
        position_enu_m: Any,
        velocity_enu_mps: Any,
        reference_velocity_enu_mps: Any,
        attitude_error: Any,
        omega_error_radps: Any,
        mass_estimate_kg: Any,
        inertia_estimate_kgm2: Any,
        thrust_n: Any,
        force_enu_n: Any,
        vehicle_ids: Any,
        offsets_enu_m: Any,
        source: str,
        controller: str,
        team: str,
        name: str,
        mass_true_kg: Any = None,
        sysids: Any = None,
        extra: Mapping[str, Any] | None = None,
    ) -> FlightLog:
        """Make a log from whole arrays (the simulation). Shapes as in the class docstring.

        ``mass_true_kg=None`` means unknown (all NaN); a shape ``(n,)`` array is a constant true
        mass per vehicle. ``sysids=None`` uses the vehicle ids.
        """
        k = np.asarray(t_s).shape[0] if np.ndim(t_s) == 1 else 0
        ids = np.asarray(vehicle_ids)
        n = ids.shape[0] if ids.ndim == 1 else 0
        if mass_true_kg is None:
            mass_true = np.full((k, n), np.nan)
        else:
            mass_true = np.asarray(mass_true_kg, dtype=np.float64)
            if mass_true.shape == (n,):
                mass_true = np.broadcast_to(mass_true, (k, n))
        return cls(
            t_s=t_s,
            position_enu_m=position_enu_m,
            velocity_enu_mps=velocity_enu_mps,
            reference_velocity_enu_mps=reference_velocity_enu_mps,
            attitude_error=attitude_error,
            omega_error_radps=omega_error_radps,
            mass_estimate_kg=mass_estimate_kg,
            mass_true_kg=mass_true,
            inertia_estimate_kgm2=inertia_estimate_kgm2,
            thrust_n=thrust_n,
            force_enu_n=force_enu_n,
            vehicle_ids=ids,
            sysids=ids if sysids is None else sysids,
            offsets_enu_m=offsets_enu_m,
            source=source,
            controller=controller,
            team=team,
            name=name,
            extra=dict(extra or {}),
        )

    @property
    def n_samples(self) -> int:
        return int(self.t_s.size)

    @property
    def n_vehicles(self) -> int:
        return int(self.vehicle_ids.size)

    @property
    def period_s(self) -> float:
        """Median sample period [s] (NaN for a single sample)."""
        return float(np.median(np.diff(self.t_s))) if self.t_s.size > 1 else math.nan

    def vehicle_index(self, vehicle_id: int) -> int:
        """Position of ``vehicle_id`` along the vehicle axis; ValueError if it is not in the log."""
        hits = np.flatnonzero(self.vehicle_ids == vehicle_id)
        if hits.size == 0:
            raise ValueError(f"vehicle {vehicle_id} is not in the log {self.vehicle_ids.tolist()}")
        return int(hits[0])

    def take(self, indices: Sequence[int] | np.ndarray) -> FlightLog:
        """A new log holding only the samples at ``indices`` (increasing), metadata unchanged."""
        idx = np.asarray(indices, dtype=np.intp)
        series = {name: getattr(self, name)[idx] for name in ("t_s", *SERIES_SHAPES)}
        return FlightLog(**series, **self._metadata())

    def downsample(self, period_s: float) -> FlightLog:
        """Keep the samples at integer multiples of ``period_s`` (e.g. 0.01 to log a 1 kHz sim at
        100 Hz). Sample times must be multiples of the log period; see metrics.grid_indices."""
        _, idx = grid_indices(self.t_s, period_s)
        return self.take(idx[idx >= 0])

    def _metadata(self) -> dict[str, Any]:
        return {
            "vehicle_ids": self.vehicle_ids,
            "sysids": self.sysids,
            "offsets_enu_m": self.offsets_enu_m,
            "source": self.source,
            "controller": self.controller,
            "team": self.team,
            "name": self.name,
            "extra": dict(self.extra),
        }


#: ``estimates_record`` mass_from values: where each vehicle's initial mass estimate came from
#: ("none": no estimate at all, position mode)
MASS_FROM = ("hover", "team", "nominal", "none")
#: ``estimates_record`` inertia_from values ("none": no estimate at all, position mode)
INERTIA_FROM = ("team", "nominal", "none")


def estimates_record(
    *,
    mass_from: Sequence[str],
    inertia_from: str,
    inertia_kgm2: Any,
    inertia_estimated: bool,
) -> dict[str, Any]:
    """``FlightLog.extra["estimates"]``: what the run's law started its estimates from and
    whether it integrated the inertia estimate (JSON-ready).

    mass_from (n,): per vehicle, "hover" (mhat_i(0) from its hover thrust, gcs fly), "team"
    (the team file's estimates.mhat), "nominal" (the baseline's known mass, not estimated) or
    "none" (no law, no estimate: position mode); inertia_from: "team" (estimates.inertia_kgm2),
    "nominal" (the baseline's known inertia) or "none" (with inertia_kgm2 None);
    inertia_kgm2 (n, 3): rhohat_i(0); inertia_estimated: False when rhohat was held at
    rhohat(0) (the baseline, or a mode that does not command the torque: TORQUE_MODES).
    Raises ValueError for a value outside those.
    """
    bad = [m for m in mass_from if m not in MASS_FROM]
    if bad or inertia_from not in INERTIA_FROM:
        raise ValueError(
            f"estimates_record: mass_from expects {MASS_FROM} and inertia_from one of "
            f"{INERTIA_FROM}, got {list(mass_from)} and {inertia_from!r}"
        )
    if inertia_from == "none":
        if inertia_kgm2 is not None or inertia_estimated:
            raise ValueError("estimates_record: inertia_from 'none' has no inertia_kgm2 and "
                             "estimates nothing")
        inertia = None
    else:
        inertia = np.asarray(inertia_kgm2, dtype=np.float64)
        if inertia.shape != (len(mass_from), 3):
            raise ValueError(
                f"estimates_record: inertia_kgm2: expected shape ({len(mass_from)}, 3), "
                f"got {inertia.shape}"
            )
    return {
        "mass_from": list(mass_from),
        "inertia_from": inertia_from,
        "inertia_kgm2": None if inertia is None else inertia.tolist(),
        "inertia_estimated": bool(inertia_estimated),
    }


class FlightLogBuilder:
    """Collects a flight one sample at a time (``gcs fly``'s control tick) and builds a FlightLog.

    Not thread-safe; call ``append`` from the tick that owns the log. Every sample is checked on
    the way in, so a wrong shape fails at the tick that produced it, naming the field and sample.
    """

    def __init__(
        self,
        *,
        vehicle_ids: Sequence[int],
        offsets_enu_m: Any,
        source: str,
        controller: str,
        team: str,
        name: str,
        sysids: Sequence[int] | None = None,
        extra: Mapping[str, Any] | None = None,
    ) -> None:
        self._meta: dict[str, Any] = {
            "vehicle_ids": np.asarray(vehicle_ids),
            "sysids": np.asarray(vehicle_ids if sysids is None else sysids),
            "offsets_enu_m": np.asarray(offsets_enu_m, dtype=np.float64),
            "source": source,
            "controller": controller,
            "team": team,
            "name": name,
            "extra": dict(extra or {}),
        }
        # Validate the metadata now (with one dummy sample) rather than at build() after a flight.
        self._n = int(self._meta["vehicle_ids"].size)
        FlightLog.from_arrays(**self._dummy_series(), **self._meta)
        self._t: list[float] = []
        self._series: dict[str, list[np.ndarray]] = {name: [] for name in SERIES_SHAPES}

    def _dummy_series(self) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {"t_s": np.zeros(1)}
        for name, tail in SERIES_SHAPES.items():
            out[name] = np.zeros((1, *(self._n if s == "n" else s for s in tail)))
        return out

    def __len__(self) -> int:
        return len(self._t)

    def append(
        self,
        *,
        t_s: float,
        position_enu_m: Any,
        velocity_enu_mps: Any,
        reference_velocity_enu_mps: Any,
        attitude_error: Any = None,
        omega_error_radps: Any = None,
        mass_estimate_kg: Any = None,
        inertia_estimate_kgm2: Any = None,
        thrust_n: Any = None,
        force_enu_n: Any = None,
        mass_true_kg: Any = None,
    ) -> None:
        """Record one sample (shapes as in FlightLog without the leading k). Returns when stored.

        A series given as None is recorded unknown (NaN): ``mass_true_kg`` without a plant, the
        law's figures of a flight that runs no law (position mode). Raises ValueError on a wrong
        shape or a time that is not finite or not after the previous sample.
        """
        index = len(self._t)
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"FlightLogBuilder.append: sample {index}: t_s is not finite ({t})")
        if self._t and t <= self._t[-1]:
            raise ValueError(
                f"FlightLogBuilder.append: sample {index}: t_s = {t!r} is not after the previous "
                f"sample's {self._t[-1]!r}"
            )
        values = {
            "position_enu_m": position_enu_m,
            "velocity_enu_mps": velocity_enu_mps,
            "reference_velocity_enu_mps": reference_velocity_enu_mps,
            "attitude_error": attitude_error,
            "omega_error_radps": omega_error_radps,
            "mass_estimate_kg": mass_estimate_kg,
            "mass_true_kg": mass_true_kg,
            "inertia_estimate_kgm2": inertia_estimate_kgm2,
            "thrust_n": thrust_n,
            "force_enu_n": force_enu_n,
        }
        checked: dict[str, np.ndarray] = {}
        for name, tail in SERIES_SHAPES.items():
            expected = tuple(self._n if s == "n" else s for s in tail)
            a = (np.full(expected, np.nan) if values[name] is None
                 else np.array(values[name], dtype=np.float64))
            if a.shape != expected:
                raise ValueError(
                    f"FlightLogBuilder.append: sample {index} (t_s = {t!r}): {name}: expected "
                    f"shape {_shape_str(tail)} = {expected} for n={self._n} vehicles, got {a.shape}"
                )
            checked[name] = a
        self._t.append(t)
        for name, a in checked.items():
            self._series[name].append(a)

    def build(self, extra: Mapping[str, Any] | None = None) -> FlightLog:
        """The FlightLog of the samples so far; ``extra`` is merged over the builder's extra.

        Raises ValueError if no sample was appended.
        """
        if not self._t:
            raise ValueError("FlightLogBuilder.build: no samples were appended")
        meta = dict(self._meta)
        meta["extra"] = {**meta["extra"], **dict(extra or {})}
        series = {name: np.stack(values) for name, values in self._series.items()}
        return FlightLog(t_s=np.asarray(self._t), **series, **meta)


# --------------------------------------------------------------------------------------------------
# CSV


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
