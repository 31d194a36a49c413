"""The time series of one formation flight (sim or fly): the FlightLog record.

Frames and units: every vector is in the app's world frame ENU (x east, y north, z up; the paper's
frame), SI units as the field suffixes say. ``t_s = 0`` is the start of the formation phase.
Shapes: ``k`` samples, ``n`` vehicles.

* ``FlightLog`` is frozen; its arrays are read-only float64 (ids and sysids int64) copies.
* ``FlightLog.from_arrays`` makes one from whole arrays (the simulation);
  ``flightlog_builder.FlightLogBuilder`` appends one sample at a time (``gcs fly``).
* ``flightlog_csv.save_timeseries`` / ``load_timeseries`` write and read it as a CSV that
  round-trips exactly (the format is described there).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gcs.metrics import grid_indices

SOURCES = ("sim", "fly")
#: no law ran: the vehicles' own position controllers flew their formation slots (gcs fly's
#: position mode, gcs/control/slots.py)
AUTOPILOT_CONTROLLER = "autopilot"
CONTROLLERS = ("adaptive", "baseline", AUTOPILOT_CONTROLLER)

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


def shape_str(shape: Sequence[str | int]) -> str:
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
                    f"FlightLog.{name}: expected shape {shape_str(('k', *tail))} = {expected} "
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


# --------------------------------------------------------------------------------------------------
# CSV
