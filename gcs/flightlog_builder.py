"""``FlightLogBuilder``: a flight collected one sample at a time (``gcs fly``'s tick), then built
into a FlightLog."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gcs.flightlog import SERIES_SHAPES, FlightLog, shape_str


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
                    f"shape {shape_str(tail)} = {expected} for n={self._n} vehicles, got {a.shape}"
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
