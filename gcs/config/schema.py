"""Team configuration schema: ConfigError and the frozen dataclasses (ENU metres).

Every problem raises ConfigError with one line "<file>: <key path>: <problem>" (plus "(line N)"
when the value came from a YAML file). The schema is documented in docs/configuration.md. The
named choices (modes, actions) are in modes, the `fly:` section's dataclasses in fly_schema, the
`network:` section's in network_schema, ConfigError in errors; all are re-exported here.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from gcs.config.declare import key
from gcs.config.errors import ConfigError
from gcs.config.fault_schema import (  # noqa: F401  (re-exported: this module's before the split)
    Fault,
    FaultConfig,
    LinkLossFault,
    MotorEfficiencyFault,
    PacketLossFault,
)
from gcs.config.fly_schema import (  # noqa: F401  (re-exported: this module's before the split)
    GO_TO_START_ENABLED,
    RESPONSE_KEYS,
    FlyConfig,
    FlyModeConfig,
    FormationCheckConfig,
    GeofenceConfig,
    GoToStartConfig,
    PositionModeConfig,
    ResponseConfig,
    Vec3,
)
from gcs.config.modes import (  # noqa: F401  (re-exported: this module's before the split)
    AUTO_MODES,
    DERIVATIVE_METHODS,
    FAULT_KINDS,
    FLY_ACTIONS,
    FLY_CONTROL_MODES,
    FLY_HEADINGS,
    FLY_INITIAL_MASSES,
    FLY_MODES,
    FLY_SCHEDULING,
    FLY_STARTS,
    JITTER_KINDS,
    LAWS,
    MODES,
    POSITION_MODE,
    SIM_MODES,
    TORQUE_MODES,
    ControlMode,
    as_strings,
)
from gcs.config.network_schema import NetworkConfig
from gcs.control.gains import LawGains

if TYPE_CHECKING:
    from gcs.config.yamlnode import Node

GRAVITY_MPS2 = 9.81
THRUST_MARGIN = 1.2  # max collective thrust must be >= THRUST_MARGIN * m g when a plant is given

ZERO3: Vec3 = (0.0, 0.0, 0.0)


def _choices(options: Sequence[str]) -> str:
    return ", ".join(repr(o) for o in as_strings(options))


# --------------------------------------------------------------------------------------------
# The configuration, as dataclasses. Frames: ENU world (x east, y north, z up), FLU body.


#: Gains of the paper's law (Section V; k_eps: attitude feedback of the rates mode [1/s]). The
#: config holds the law's own record, so what is validated is exactly what the law receives.
Gains = LawGains
GAIN_NAMES = tuple(name for name in LawGains._fields if name != "gravity_mps2")


def _gains(node: Node, default: Any) -> Gains:
    """controller.gains: every gain of the law > 0; k_eps_yaw (the rates mode's yaw feedback)
    defaults to k_eps; phi_horizontal (the horizontal velocity's weight in the estimator's phi)
    in [0, 1], default 1 (the paper's)."""
    optional = ("k_eps_yaw", "phi_horizontal")
    own = [name for name in GAIN_NAMES if name not in optional]
    node.keys(" ".join(own), " ".join(optional))
    values = {name: node.child(name).number(gt=0.0) for name in own}
    values["k_eps_yaw"] = node.child("k_eps_yaw").number(values["k_eps"], gt=0.0)
    values["phi_horizontal"] = node.child("phi_horizontal").number(1.0, ge=0.0, le=1.0)
    return Gains(**values)


@dataclass(frozen=True, slots=True)
class DerivativeConfig:
    """How u' and u'' are obtained: "model" (from the state and estimates) or "levant" (28)."""

    method: str = key("model", choices=DERIVATIVE_METHODS)
    levant_lipschitz: float = key(1e4, gt=0.0)
    levant_substep_s: float = key(1e-4, gt=0.0)


@dataclass(frozen=True, slots=True)
class ControllerConfig:
    law: str = key(choices=LAWS)
    mode: ControlMode = key(choices=MODES)  # rates, actuators or attitude (gcs fly only)
    gains: Gains = key(read=_gains)
    derivative: DerivativeConfig = key(DerivativeConfig())


@dataclass(frozen=True, slots=True)
class Cosine:
    """amplitude * cos(2 pi t / period_s + phase_rad), amplitude in m/s."""

    amplitude: float = key()
    period_s: float = key(gt=0.0)
    phase_rad: float = key(0.0)


@dataclass(frozen=True, slots=True)
class AxisReference:
    constant: float = key(0.0)
    cosines: tuple[Cosine, ...] = key(())


@dataclass(frozen=True, slots=True)
class ReferenceVelocity:
    """v_r(t) [m/s, ENU] = constant + sum amplitude cos(omega t + phase), per axis."""

    x: AxisReference = key()
    y: AxisReference = key()
    z: AxisReference = key()

    def max_abs_acceleration_z(self) -> float:
        """varrho = sum |amp| 2 pi / period_s over z [m/s^2]: sup|v_r,z'| (exact for one cosine)."""
        return sum(abs(c.amplitude) * 2.0 * math.pi / c.period_s for c in self.z.cosines)

    def as_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(constant (3,), amplitude (3,K), omega_radps (3,K), phase_rad (3,K)), zero-padded."""
        axes = (self.x, self.y, self.z)
        k = max(len(a.cosines) for a in axes)
        amplitude, omega, phase = np.zeros((3, k)), np.zeros((3, k)), np.zeros((3, k))
        for r, axis in enumerate(axes):
            for c, cos in enumerate(axis.cosines):
                amplitude[r, c] = cos.amplitude
                omega[r, c] = 2.0 * math.pi / cos.period_s
                phase[r, c] = cos.phase_rad
        return np.array([a.constant for a in axes]), amplitude, omega, phase

    def evaluate(self, t_s: float, order: int = 0) -> np.ndarray:
        """The order-th time derivative of v_r at t_s, shape (3,), ENU [m/s^(1+order)]."""
        constant, amplitude, omega, phase = self.as_arrays()
        terms = amplitude * omega**order * np.cos(omega * t_s + phase + order * math.pi / 2.0)
        return terms.sum(axis=1) + (constant if order == 0 else 0.0)


@dataclass(frozen=True, slots=True)
class Edge:
    """Undirected edge between vehicle ids i and j with weight a_ij = a_ji."""

    i: int = key()
    j: int = key()
    weight: float = key(1.0, gt=0.0)


@dataclass(frozen=True, slots=True)
class GraphConfig:
    edges: tuple[Edge, ...] = key()  # [i, j], [i, j, weight] or {i, j, weight} (reader.py)


def whole_ratio(high_hz: float, low_hz: float) -> int | None:
    """``high_hz / low_hz`` when it is a whole number >= 1 (to 1e-9 of itself), else None: the one
    rule every pair of a team's rates obeys (plant steps per control tick, ticks per time-series
    sample)."""
    if not (high_hz > 0.0 and low_hz > 0.0):
        return None
    ratio = high_hz / low_hz
    whole = round(ratio)
    return whole if whole >= 1 and abs(ratio - whole) <= 1e-9 * ratio else None


@dataclass(frozen=True, slots=True)
class SimConfig:
    plant_rate_hz: float = key(1000.0, gt=0.0)
    controller_rate_hz: float = key(1000.0, gt=0.0)
    # the ground station's links in gcs sim (gcs/sim/link.py): one-way delay each way [s],
    # loss probability each way, and the seed of the losses
    link_delay_s: float = key(0.0, ge=0.0, le=1.0)
    link_loss: float = key(0.0, ge=0.0, lt=1.0)
    link_seed: int = key(0, ge=0)
    # the vehicles' own loops in gcs sim: idealised (a 50 rad/s rate loop, no motor lag) or an
    # autopilot's recorded response (gcs/control/cascade.py: rate loop, yaw, thrust lag)
    autopilot: str = key("ideal", choices=("ideal", "px4", "ardupilot", "nominal"))
    # with px4 or ardupilot: the law reads that autopilot's telemetry errors (gcs/sim/noise.py)
    telemetry_noise: bool = key(True)

    @property
    def plant_dt_s(self) -> float:
        return 1.0 / self.plant_rate_hz

    @property
    def controller_dt_s(self) -> float:
        return 1.0 / self.controller_rate_hz

    @property
    def plant_steps_per_tick(self) -> int:
        return round(self.plant_rate_hz / self.controller_rate_hz)


@dataclass(frozen=True, slots=True)
class MissionConfig:
    duration_s: float = key(gt=0.0)


@dataclass(frozen=True, slots=True)
class Airframe:
    """Quadrotor geometry of eq. (51): d_i = arm_length_m, C_i = anti_torque_m."""

    arm_length_m: float = key(gt=0.0)
    anti_torque_m: float = key(gt=0.0)
    rotor_thrust_max_n: float = key(gt=0.0)
    motor_time_constant_s: float = key(0.0, ge=0.0)  # first-order rotor lag in the emulator

    @property
    def max_thrust_n(self) -> float:
        return 4.0 * self.rotor_thrust_max_n


@dataclass(frozen=True, slots=True)
class PlantParams:
    """True parameters: for the simulated plant and emulator only, never for the controller."""

    mass_kg: float = key(gt=0.0)
    inertia_kgm2: Vec3 = key(gt=0.0)  # diag(Jx, Jy, Jz), body frame


@dataclass(frozen=True, slots=True)
class InitialState:
    position_enu_m: Vec3 = key()
    velocity_enu_mps: Vec3 = key(ZERO3)
    attitude_rpy_rad: Vec3 = key(ZERO3)
    body_rates_radps: Vec3 = key(ZERO3)


@dataclass(frozen=True, slots=True)
class Estimates:
    """Initial adaptive states: mhat = mhat_i(0) of (24) (NOT a mass: alpha_m mhat/phi is)."""

    mhat: float = key()  # a number > 0 or from_hover (reader.py)
    inertia_kgm2: Vec3 = key(gt=0.0)  # rhohat(0) = Jhat(0) diagonal
    mass_bound_kg: float | None = key(None, gt=0.0)  # mbar_i of Proposition 2
    # `mhat: from_hover`: gcs fly takes mhat_i(0) from the thrust the vehicle reports while it
    # holds (ATTITUDE_TARGET); mhat above is then the stand-in phi(0) m / alpha_m (m: the plant
    # mass, else mass_bound_kg) that gcs sim flies and that the flight replaces
    from_hover: bool = key(False, internal=True)


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """GCS side of a vehicle's MAVLink UDP link (local_port 0: any free port).

    ``learn_remote``: the vehicle's address is the source of its first valid message (its
    ``remote_port``, if given, is only where the GCS sends until then; None: nowhere). Vehicles
    with the same nonzero ``local_port`` share that GCS port, told apart by sysid.
    """

    local_port: int = key(ge=0, le=65535)
    # None only with learn_remote and no remote_port
    remote_host: str | None = key()
    remote_port: int | None = key(ge=1, le=65535)  # None only with learn_remote
    learn_remote: bool = key(False)

    @classmethod
    def px4_sitl(cls, sysid: int) -> LinkConfig:
        """PX4 SITL instance sysid-1: GCS listens on 14540+i, vehicle listens on 14580+i."""
        return cls(14540 + sysid - 1, "127.0.0.1", 14580 + sysid - 1)


@dataclass(frozen=True, slots=True)
class VehicleConfig:
    id: int = key(ge=1)
    sysid: int = key(ge=1, le=255)
    offset_enu_m: Vec3 = key()  # theta_i, so theta_ij = theta_i - theta_j
    initial: InitialState = key()
    estimates: Estimates = key()  # read with the plant and gains (reader.py)
    airframe: Airframe = key()
    link: LinkConfig = key(optional=True)  # absent: PX4 SITL's ports for the sysid (reader.py)
    plant: PlantParams | None = key(None)
    nominal_mass_kg: float | None = key(None, gt=0.0)  # the non-adaptive baseline's mass
    # The baseline's frozen inertia (Jhat is not adapted); None: the initial estimate.
    nominal_inertia_kgm2: Vec3 | None = key(None, gt=0.0)

    @property
    def baseline_inertia_kgm2(self) -> Vec3:
        """The inertia the non-adaptive baseline uses: nominal_inertia_kgm2, else estimates."""
        if self.nominal_inertia_kgm2 is not None:
            return self.nominal_inertia_kgm2
        return self.estimates.inertia_kgm2

    @property
    def mass_bound_kg(self) -> float | None:
        """mbar_i for Proposition 2: estimates.mass_bound_kg, else the plant mass, else None."""
        if self.estimates.mass_bound_kg is not None:
            return self.estimates.mass_bound_kg
        return self.plant.mass_kg if self.plant is not None else None




FRAME_VEHICLES = ("own", "shared")


def _on_earth(node: Node, lat_lon_alt: Vec3) -> None:
    for k, (name, low, high) in enumerate((("latitude", -90.0, 90.0),
                                           ("longitude", -180.0, 180.0),
                                           ("altitude", -1000.0, 20000.0))):
        if not low <= lat_lon_alt[k] <= high:
            node.fail(f"[lat_deg, lon_deg, alt_m]: {name} {lat_lon_alt[k]!r} outside "
                      f"[{low:g}, {high:g}]")
#: PX4 SITL's default home: the bundled emulator's team-frame origin (lat deg, lon deg, alt m)
DEFAULT_FRAME_ORIGIN = (47.397742, 8.545594, 488.0)


@dataclass(frozen=True, slots=True)
class FrameConfig:
    """The `frame:` section: how `gcs fly` ties each vehicle's local frame to the team frame."""

    origin: Vec3 = key(DEFAULT_FRAME_ORIGIN, check=_on_earth)  # lat deg, lon deg, alt m
    # own: each vehicle's LOCAL_POSITION_NED is relative to its own EKF origin, read from the
    # vehicle (GPS_GLOBAL_ORIGIN, else HOME_POSITION); shared: every vehicle's local frame is the
    # team frame (no origin needed)
    vehicles: str = key("own", choices=FRAME_VEHICLES)
    # a vehicle's origin this far from `origin`: refused
    max_origin_distance_m: float = key(1000.0, gt=0.0)


@dataclass(frozen=True, slots=True, kw_only=True)
class TeamConfig:
    """The whole team file (each section's keys declared by its dataclass; the vehicles, the
    graph and the faults are read with what they depend on: gains, ids, the mission's length)."""

    name: str = key()
    mission: MissionConfig = key()
    controller: ControllerConfig = key()
    reference_velocity: ReferenceVelocity = key()
    graph: GraphConfig = key()
    vehicles: tuple[VehicleConfig, ...] = key()
    sim: SimConfig = key(SimConfig())
    faults: tuple[Fault, ...] = key(())
    fly: FlyConfig = key(FlyConfig())
    frame: FrameConfig = key(FrameConfig())
    network: NetworkConfig = key(NetworkConfig())  # gcs agent's Zenoh bus (network_schema.py)
    source_path: str = key("<dict>", internal=True)

    @property
    def n(self) -> int:
        return len(self.vehicles)

    def ids(self) -> tuple[int, ...]:
        return tuple(v.id for v in self.vehicles)

    def sysids(self) -> tuple[int, ...]:
        return tuple(v.sysid for v in self.vehicles)

    def index_of(self, vehicle_id: int) -> int:
        """Row of vehicle_id in every (n, ...) array; KeyError if there is no such vehicle."""
        for k, v in enumerate(self.vehicles):
            if v.id == vehicle_id:
                return k
        raise KeyError(f"no vehicle with id {vehicle_id}; ids are {self.ids()}")

    def vehicle(self, vehicle_id: int) -> VehicleConfig:
        return self.vehicles[self.index_of(vehicle_id)]

    def adjacency(self) -> np.ndarray:
        """(n, n) symmetric weights a_ij, rows and columns in vehicle order."""
        a = np.zeros((self.n, self.n))
        for e in self.graph.edges:
            i, j = self.index_of(e.i), self.index_of(e.j)
            a[i, j] = a[j, i] = e.weight
        return a

    def laplacian(self) -> np.ndarray:
        """L = D - A, (n, n)."""
        a = self.adjacency()
        return np.diag(a.sum(axis=1)) - a

    def _rows(self, get: Callable[[VehicleConfig], Any]) -> np.ndarray:
        return np.array([get(v) for v in self.vehicles], dtype=float)

    def offsets_enu_m(self) -> np.ndarray:
        return self._rows(lambda v: v.offset_enu_m).reshape(self.n, 3)

    def initial_positions_enu_m(self) -> np.ndarray:
        return self._rows(lambda v: v.initial.position_enu_m).reshape(self.n, 3)

    def initial_velocities_enu_mps(self) -> np.ndarray:
        return self._rows(lambda v: v.initial.velocity_enu_mps).reshape(self.n, 3)

    def initial_attitudes_rpy_rad(self) -> np.ndarray:
        return self._rows(lambda v: v.initial.attitude_rpy_rad).reshape(self.n, 3)

    def initial_body_rates_radps(self) -> np.ndarray:
        return self._rows(lambda v: v.initial.body_rates_radps).reshape(self.n, 3)

    def initial_mhat(self) -> np.ndarray:
        """(n,) mhat_i(0) of (24)."""
        return self._rows(lambda v: v.estimates.mhat)

    def initial_inertia_estimates_kgm2(self) -> np.ndarray:
        return self._rows(lambda v: v.estimates.inertia_kgm2).reshape(self.n, 3)

    def max_thrusts_n(self) -> np.ndarray:
        return self._rows(lambda v: v.airframe.max_thrust_n)

    def has_plants(self) -> bool:
        return all(v.plant is not None for v in self.vehicles)

    def _need(self, key: str, get: Callable[[VehicleConfig], Any], why: str) -> np.ndarray:
        for k, v in enumerate(self.vehicles):
            if get(v) is None:
                raise ConfigError(
                    self.source_path,
                    f"vehicles[{k}].{key}",
                    f"missing: {why} (vehicle {v.id}, sysid {v.sysid})",
                )
        return self._rows(get)

    def true_masses_kg(self) -> np.ndarray:
        """(n,) plant masses; ConfigError if a vehicle has no plant."""
        return self._need(
            "plant", lambda v: v.plant and v.plant.mass_kg, "the true mass is needed, give a plant"
        )

    def true_inertias_kgm2(self) -> np.ndarray:
        get = lambda v: v.plant and v.plant.inertia_kgm2  # noqa: E731
        return self._need("plant", get, "the true inertia is needed, give a plant").reshape(
            self.n, 3
        )

    def nominal_masses_kg(self) -> np.ndarray:
        return self._need(
            "nominal_mass_kg", lambda v: v.nominal_mass_kg, "the baseline law needs nominal_mass_kg"
        )

    def with_hover_masses(self) -> TeamConfig:
        """The same team with every vehicle's initial mass estimate taken from its hover
        (`estimates.mhat: from_hover`; each needs mbar: mass_bound_kg or a plant)."""
        for v in self.vehicles:
            if v.mass_bound_kg is None:
                raise ConfigError(self.source_path, "fly.initial_mass",
                                  f"from_hover needs vehicle {v.id}'s estimates.mass_bound_kg "
                                  "(Proposition 2's mbar) or a plant")
        vehicles = tuple(dataclasses.replace(v, estimates=dataclasses.replace(
            v.estimates, from_hover=True)) for v in self.vehicles)
        return dataclasses.replace(self, vehicles=vehicles)

    def with_law(self, law: str) -> TeamConfig:
        """The same team flown with another law ("adaptive" | "baseline"), checked."""
        if law not in LAWS:
            raise ConfigError(
                self.source_path, "controller.law", f"expected one of {_choices(LAWS)}, got {law!r}"
            )
        team = dataclasses.replace(self, controller=dataclasses.replace(self.controller, law=law))
        if law == "baseline":
            team.nominal_masses_kg()
        return team


def initial_phi(vehicle: VehicleConfig, gains: Gains) -> float:
    """phi_i(0) = 2 + (1/(3 sigma_a)) sum_k w_k sat(v_i,k(0)), sat(x) = sigma_a tanh(x / sigma_a),
    w = (phi_horizontal, phi_horizontal, 1).

    (= 2 + sum_k tanh(v_i,k(0)) / 3 for the paper's sigma_a = 1 and w = 1; the law's phi in
    gcs/control/position.py.)
    """
    s = gains.sigma_a
    w = (gains.phi_horizontal, gains.phi_horizontal, 1.0)
    return 2.0 + sum(wk * s * math.tanh(x / s)
                     for wk, x in zip(w, vehicle.initial.velocity_enu_mps, strict=True)) / (3.0 * s)


def proposition2_min_mhat(vehicle: VehicleConfig, gains: Gains) -> float | None:
    """(phi_i(0) - 1) mbar_i / alpha_m, the least mhat_i(0) of Proposition 2; None: no mbar_i."""
    mbar = vehicle.mass_bound_kg
    return None if mbar is None else (initial_phi(vehicle, gains) - 1.0) * mbar / gains.alpha_m
